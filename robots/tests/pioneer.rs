//! The Pioneer 3-DX backend: the ARCOS codec against packets written out by hand, and the
//! client against the loopback server (and against hand-made misbehaving servers).

use std::f64::consts::PI;
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use nalgebra::DVector;
use wheelid_core::condition::{ConditionSettings, condition, suggest_cutoff};
use wheelid_core::{Odometry, Recording, Robot, RobotError};
use wheelid_models::regressor::regression;
use wheelid_robots::pioneer::arcos::{
    ANGLE_UNIT_RAD, Odometer, Packet, PacketReader, Sip, SipIo, SonarReading, checksum, cmd,
};
use wheelid_robots::pioneer::{
    ArcosServer, Pacing, Pioneer, PioneerSettings, RobotIdentity, ServerHandle,
};
use wheelid_robots::{Excitation, RobotProfile, SimRobot, SimSettings};

// ---------------------------------------------------------------------------------------------
// Codec

/// Client packets written out by hand from the manual's rules (header FA FB; count = bytes
/// after it; id; argument type 0x3B/0x1B + |value| LSB first; checksum = sum of big-endian byte
/// pairs mod 2¹⁶, high byte first). The SYNC0–SYNC2 and ENABLE 1 strings, and SETA −1000, also
/// appear verbatim in the constant tables of an independently written HCS12 Pioneer 3-DX client
/// (found by code search).
#[test]
fn client_packets_match_bytes_written_out_by_hand() {
    let cases: [(&str, Packet, &[u8]); 12] = [
        (
            "SYNC0",
            Packet::command(cmd::SYNC0),
            &[0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00],
        ),
        (
            "SYNC1",
            Packet::command(cmd::SYNC1),
            &[0xFA, 0xFB, 0x03, 0x01, 0x00, 0x01],
        ),
        (
            "SYNC2",
            Packet::command(cmd::SYNC2),
            &[0xFA, 0xFB, 0x03, 0x02, 0x00, 0x02],
        ),
        (
            "PULSE",
            Packet::command(cmd::PULSE),
            &[0xFA, 0xFB, 0x03, 0x00, 0x00, 0x00],
        ),
        (
            "OPEN",
            Packet::command(cmd::OPEN),
            &[0xFA, 0xFB, 0x03, 0x01, 0x00, 0x01],
        ),
        (
            "CLOSE",
            Packet::command(cmd::CLOSE),
            &[0xFA, 0xFB, 0x03, 0x02, 0x00, 0x02],
        ),
        // 0x043B + 0x0100 = 0x053B.
        (
            "ENABLE 1",
            Packet::command_int(cmd::ENABLE, 1),
            &[0xFA, 0xFB, 0x06, 0x04, 0x3B, 0x01, 0x00, 0x05, 0x3B],
        ),
        // 300 = 0x012C; 0x0B3B + 0x2C01 = 0x373C.
        (
            "VEL 300",
            Packet::command_int(cmd::VEL, 300),
            &[0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0x2C, 0x01, 0x37, 0x3C],
        ),
        // Negative: type 0x1B, |−30| = 0x001E; 0x151B + 0x1E00 = 0x331B.
        (
            "RVEL -30",
            Packet::command_int(cmd::RVEL, -30),
            &[0xFA, 0xFB, 0x06, 0x15, 0x1B, 0x1E, 0x00, 0x33, 0x1B],
        ),
        // 0x0B3B + 0xFF7F = 0x1_0ABA: the sum wraps to 0x0ABA.
        (
            "VEL 32767",
            Packet::command_int(cmd::VEL, 32767),
            &[0xFA, 0xFB, 0x06, 0x0B, 0x3B, 0xFF, 0x7F, 0x0A, 0xBA],
        ),
        // SETA (5) −1000: 0x051B + 0xE803 = 0xED1E.
        (
            "SETA -1000",
            Packet::command_int(5, -1000),
            &[0xFA, 0xFB, 0x06, 0x05, 0x1B, 0xE8, 0x03, 0xED, 0x1E],
        ),
        // A string argument (ARIA comStr): 0x2B, length, bytes; odd body 0F 2B 02 68 69:
        // 0x0F2B + 0x0268 = 0x1193, then ^ 0x69 = 0x11FA.
        (
            "SAY \"hi\"",
            Packet::command_str(15, b"hi").expect("fits"),
            &[0xFA, 0xFB, 0x07, 0x0F, 0x2B, 0x02, 0x68, 0x69, 0x11, 0xFA],
        ),
    ];
    for (name, packet, bytes) in cases {
        assert_eq!(packet.to_bytes(), bytes, "{name}");
        assert_eq!(Packet::from_frame(bytes).expect(name), packet, "{name}");
    }
    assert_eq!(
        Packet::from_frame(&[0xFA, 0xFB, 0x06, 0x15, 0x1B, 0x1E, 0x00, 0x33, 0x1B])
            .expect("RVEL")
            .int_arg()
            .expect("int"),
        Some(-30)
    );
}

/// A standard SIP built byte by byte from the manual's SIP table.
fn hand_built_sip() -> Vec<u8> {
    let body = [
        0x33, // type: moving
        0xD2, 0x04, // XPOS 1234 mm
        0x00, 0x7D, // YPOS 32000 = −768 mm as a signed 15-bit counter
        0x00, 0xFC, // THPOS −1024 = −π/2
        0xFA, 0x00, // L VEL 250 mm/s
        0x3E, 0x01, // R VEL 318 mm/s
        0x7D, // BATTERY 12.5 V
        0x00, 0x01, // STALL AND BUMPERS: bit 8, right wheel stalled
        0x00, 0xFC, // CONTROL −1024
        0x01, 0x00, // FLAGS: motors enabled
        0x2D, // COMPASS 45 (90°)
        0x02, // SONAR COUNT
        0x03, 0xDC, 0x05, // sonar 3: 1500 mm
        0x04, 0x88, 0x13, // sonar 4: 5000 mm
        0x00, 0x01, 0x80, 0xFF, 0x00, // GRIP_STATE, ANPORT 1, ANALOG 128, DIGIN FF, DIGOUT 0
        0x7D, 0x00, // BATTERYX10 125
        0x00, // CHARGESTATE
        0x73, 0x00, // ROTVEL 115 = 11.5 °/s
        0x00, 0x00, // FAULTFLAGS
    ];
    // 38 bytes; the pair sum, added up by hand: 0x33D2 + 0x0400 + 0x7D00 + 0xFCFA + 0x003E +
    // 0x017D + 0x0001 + 0x00FC + 0x0100 + 0x2D02 + 0x03DC + 0x0504 + 0x8813 + 0x0001 + 0x80FF
    // + 0x007D + 0x0000 + 0x7300 + 0x0000 = 0x67F6 (mod 2¹⁶).
    assert_eq!(checksum(&body), 0x67F6);
    let mut frame = vec![0xFA, 0xFB, 40];
    frame.extend_from_slice(&body);
    frame.extend_from_slice(&[0x67, 0xF6]);
    frame
}

#[test]
fn a_hand_built_sip_decodes_field_by_field() {
    let frame = hand_built_sip();
    let sip = Sip::decode(&Packet::from_frame(&frame).expect("frame")).expect("sip");
    let expected = Sip {
        moving: true,
        xpos: 1234,
        ypos: 32000,
        thpos: -1024,
        l_vel: 250,
        r_vel: 318,
        battery: 125,
        stall_bumpers: 0x0100,
        control: -1024,
        flags: 1,
        compass: 45,
        sonars: vec![
            SonarReading {
                number: 3,
                range: 1500,
            },
            SonarReading {
                number: 4,
                range: 5000,
            },
        ],
        io: Some(SipIo {
            grip_state: 0,
            anport: 1,
            analog: 128,
            digin: 0xFF,
            digout: 0,
        }),
        battery_x10: Some(125),
        charge_state: Some(0),
        rot_vel: Some(115),
        fault_flags: Some(0),
    };
    assert_eq!(sip, expected);
    assert!(sip.motors_enabled() && sip.stalled());
    // Encoding gives the same bytes back.
    assert_eq!(sip.to_packet().expect("encode").to_bytes(), frame);

    // v = (250 + 318)/2 = 284 mm/s; ω = (318 − 250) mm/s / 0.34 m = 0.2 rad/s.
    let mut odo = Odometer::new(0.34);
    let (v, w, pose) = odo.update(&sip);
    assert!(
        (v - 0.284).abs() < 1e-12 && (w - 0.2).abs() < 1e-12,
        "{v} {w}"
    );
    assert_eq!((pose.x, pose.y), (1.234, -0.768));
    assert!((pose.heading + PI / 2.0).abs() < 1e-12);

    // The short SIP of old firmware (nothing after the sonar readings) decodes too.
    let short = Sip {
        sonars: Vec::new(),
        io: None,
        battery_x10: None,
        charge_state: None,
        rot_vel: None,
        fault_flags: None,
        ..expected
    };
    let packet = short.to_packet().expect("encode");
    assert_eq!(packet.data().len(), 19);
    assert_eq!(Sip::decode(&packet).expect("decode"), short);
}

fn protocol_message(result: Result<impl std::fmt::Debug, RobotError>) -> String {
    match result {
        Err(RobotError::Protocol(m)) => m,
        other => panic!("expected a protocol error, got {other:?}"),
    }
}

#[test]
fn bad_checksum_header_count_and_truncation_are_protocol_errors() {
    let good = hand_built_sip();

    let mut bad_sum = good.clone();
    let n = bad_sum.len();
    bad_sum[n - 1] ^= 0x01;
    let m = protocol_message(Packet::from_frame(&bad_sum));
    assert!(
        m.contains("checksum") && m.contains("0x67F7") && m.contains("0x67F6"),
        "{m}"
    );

    let mut bad_header = good.clone();
    bad_header[1] = 0xFC;
    let m = protocol_message(Packet::from_frame(&bad_header));
    assert!(m.contains("header") && m.contains("FA FC"), "{m}");

    let m = protocol_message(Packet::from_frame(&good[..good.len() - 3]));
    assert!(m.contains("truncated"), "{m}");
    let m = protocol_message(Packet::from_frame(&[0xFA, 0xFB, 0x02, 0x00, 0x00]));
    assert!(m.contains("byte count 2"), "{m}");

    // A frame whose checksum is right but whose SIP ends inside a field.
    let cut = Packet::new(0x32, good[4..4 + 12].to_vec()).expect("packet");
    let m = protocol_message(Sip::decode(&cut));
    assert!(m.contains("STALL AND BUMPERS"), "{m}");
    let m = protocol_message(Sip::decode(&Packet::command(cmd::SYNC2)));
    assert!(m.contains("not a standard SIP"), "{m}");

    // In a stream: the bad packet is reported, the next good one still decodes.
    let mut reader = PacketReader::new();
    reader.push(&bad_sum);
    reader.push(&good);
    assert!(protocol_message(reader.next_packet()).contains("checksum"));
    let next = reader.next_packet().expect("good").expect("whole");
    assert_eq!(next.id(), 0x33);
}

fn sip_at(xpos: u16, ypos: u16, thpos: i16) -> Sip {
    Sip {
        xpos,
        ypos,
        thpos,
        ..Sip::default()
    }
}

#[test]
fn position_counters_wrap_at_15_bits_and_the_heading_unwraps() {
    let mut odo = Odometer::new(0.34);
    // Start 8 mm short of the top of the counter, heading just below +π.
    odo.update(&sip_at(32_760, 5, 2040));
    assert_eq!(odo.pose().x, -0.008); // 32 760 read as a signed 15-bit number
    // +20 mm crosses 32 767 → 0: counter 12; −10 mm crosses 0 → 32 767: counter 32 763.
    odo.update(&sip_at(12, 32_763, -2040));
    let p = odo.pose();
    assert_eq!((p.x, p.y), (0.012, -0.005));
    // THPOS 2040 → −2040 is +16 units (+0.0245 rad), not −4080.
    assert!((p.heading - 2056.0 * ANGLE_UNIT_RAD).abs() < 1e-12);
    // Keep turning: after another 4096 units the heading has gone a full turn further.
    for th in [-1000, 0, 1000, 2040] {
        odo.update(&sip_at(12, 32_763, th));
    }
    assert!((odo.pose().heading - (2040.0 + 4096.0) * ANGLE_UNIT_RAD).abs() < 1e-12);
    // Driving on for 40 m in 4 m steps: the counter wraps once more, x keeps growing.
    let mut x: i64 = 12;
    for _ in 0..10 {
        x += 4000;
        odo.update(&sip_at((x % 32_768) as u16, 32_763, 2040));
    }
    assert_eq!(odo.pose().x, 40.012);
}

// ---------------------------------------------------------------------------------------------
// Client against the loopback server

fn settings_for(server: &ServerHandle) -> PioneerSettings {
    PioneerSettings {
        port: server.url(),
        timeout_s: 5.0,
        ..PioneerSettings::default()
    }
}

/// The command the simulated robot gets after the protocol's rounding: whole mm/s, whole °/s.
fn on_the_wire(v_ref: f64, w_ref: f64) -> (f64, f64) {
    (
        (v_ref * 1000.0).round() / 1000.0,
        w_ref.to_degrees().round().to_radians(),
    )
}

/// Drives `robot` with `excitation` for `n` periods; returns the rows (report at t_k, command
/// as the robot acts on it after report k, i.e. what `send` returned), starting with the
/// report at t = 0 (the SIP read by `connect`).
fn drive(robot: &mut Pioneer, excitation: &Excitation, n: usize) -> Vec<(Odometry, f64, f64)> {
    let mut rows = Vec::with_capacity(n + 1);
    let mut report = robot.last_report();
    for _ in 0..n {
        let (v_ref, w_ref) = excitation.at(report.t);
        let (v, w) = robot.send(v_ref, w_ref).expect("send");
        assert_eq!((v, w), on_the_wire(v_ref, w_ref));
        rows.push((report, v, w));
        report = robot.read().expect("read");
    }
    rows.push((report, 0.0, 0.0));
    rows
}

#[test]
fn a_lockstep_session_follows_the_simulator_to_the_protocol_resolution() {
    let profile = RobotProfile::pioneer3dx();
    let sim = SimSettings::default();
    let server =
        ArcosServer::spawn(profile.clone(), sim.clone(), Pacing::LockStep).expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    assert_eq!(
        robot.identity(),
        &RobotIdentity {
            name: "pioneer3dx".into(),
            class: "Pioneer".into(),
            subclass: "p3dx-sh".into(),
        }
    );
    assert_eq!(robot.name(), "pioneer");
    assert_eq!(robot.period_s(), 0.1);
    let first = robot.last_report();
    assert_eq!((first.t, first.v, first.w), (0.0, 0.0, 0.0));

    // 30 s of the thesis's Pioneer excitation (four sines on each command, ω around
    // 0.75 rad/s: the robot turns about 3.5 times).
    let excitation = Excitation::thesis_pioneer();
    let mut direct = SimRobot::new(&profile, &sim).expect("sim");
    let (dv, dw) = (0.5e-3, 1e-3 / profile.track); // half a mm/s; 1 mm/s over the track
    for k in 1..=300 {
        // Report k − 1 is in (the first one from `connect`): decide, send, read report k.
        let (v_ref, w_ref) = excitation.at((k - 1) as f64 * 0.1);
        let (vq, wq) = robot.send(v_ref, w_ref).expect("send");
        // `send` returns the command as the robot acts on it: whole mm/s and °/s.
        assert_eq!((vq, wq), on_the_wire(v_ref, w_ref), "k = {k}");
        let o = robot.read().expect("read");
        let s = direct.step(vq, wq);
        assert_eq!(o.t, k as f64 * 0.1);
        assert!(
            (o.v - s.v).abs() <= dv + 1e-12,
            "k = {k}: v {} vs {}",
            o.v,
            s.v
        );
        assert!(
            (o.w - s.w).abs() <= dw + 1e-12,
            "k = {k}: ω {} vs {}",
            o.w,
            s.w
        );
        assert!((o.pose.x - s.x).abs() <= 0.5e-3 + 1e-9, "k = {k}: x");
        assert!((o.pose.y - s.y).abs() <= 0.5e-3 + 1e-9, "k = {k}: y");
        assert!(
            (o.pose.heading - s.phi).abs() <= ANGLE_UNIT_RAD / 2.0 + 1e-9,
            "k = {k}: heading {} vs {}",
            o.pose.heading,
            s.phi
        );
    }
    let last = robot.last_report();
    assert!(last.pose.heading > 6.0 * PI, "{}", last.pose.heading);
    assert!(robot.last_sip().motors_enabled());
    let (v_ref, w_ref) = excitation.at(29.9);
    let last_command = (
        (v_ref * 1000.0).round() as i16,
        w_ref.to_degrees().round() as i16,
    );
    assert_eq!(robot.command(), last_command);
    robot.stop().expect("stop");
}

fn thesis_session(server: &ServerHandle, n: usize) -> Vec<(Odometry, f64, f64)> {
    let mut robot = Pioneer::connect(&settings_for(server)).expect("connect");
    let rows = drive(&mut robot, &Excitation::thesis_pioneer(), n);
    robot.stop().expect("stop");
    rows
}

#[test]
fn lockstep_sessions_are_bit_for_bit_reproducible() {
    let server = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings::default(),
        Pacing::LockStep,
    )
    .expect("server");
    // Two sessions one after the other on the same server (each gets a fresh simulator), and
    // one on another server.
    let a = thesis_session(&server, 200);
    let b = thesis_session(&server, 200);
    let other = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings::default(),
        Pacing::LockStep,
    )
    .expect("server");
    let c = thesis_session(&other, 200);
    assert_eq!(a.len(), 201);
    assert_eq!(a, b);
    assert_eq!(a, c);
    // Another seed gives other encoder noise.
    let noisier = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings {
            seed: 2,
            ..SimSettings::default()
        },
        Pacing::LockStep,
    )
    .expect("server");
    assert_ne!(a, thesis_session(&noisier, 200));
}

/// Least squares of eq. 4.2 on one recording: θ̂ (θ1…θ6).
fn least_squares(rec: &Recording) -> [f64; 6] {
    let (fc, _) = suggest_cutoff(&[rec]).expect("cutoff");
    let cond = condition(rec, None, fc, &ConditionSettings::default()).expect("condition");
    let mut theta = [0.0; 6];
    for channel in regression(&cond).expect("regression") {
        let fit: DVector<f64> = channel
            .x
            .clone()
            .svd(true, true)
            .solve(&channel.y, 1e-12)
            .expect("solve");
        for (&i, value) in channel.params.iter().zip(fit.iter()) {
            theta[i] = *value;
        }
    }
    theta
}

fn recording(name: &str, rows: &[(f64, f64, f64, f64, f64)]) -> Recording {
    let col =
        |i: usize| -> Vec<f64> { rows.iter().map(|r| [r.0, r.1, r.2, r.3, r.4][i]).collect() };
    let mut rec = Recording::new(name, col(0), col(1), col(2), col(3), col(4)).expect("recording");
    rec.set_meta("command_hold", "zoh");
    rec.set_meta("velocity_sampling", "window_average");
    rec
}

/// A 60 s identification experiment run over TCP in lock-step: fast, and the θ̂ it gives is the
/// θ̂ of the simulator driven directly with the same (rounded) commands.
#[test]
fn identification_over_tcp_matches_the_directly_driven_simulator() {
    let profile = RobotProfile::pioneer3dx();
    let sim = SimSettings::default();
    let excitation = Excitation::random_multisine(7, 0.4, 0.25, 0.8, 1.5).expect("multisine");
    let n = 600;

    let started = Instant::now();
    let server =
        ArcosServer::spawn(profile.clone(), sim.clone(), Pacing::LockStep).expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    let rows = drive(&mut robot, &excitation, n);
    robot.stop().expect("stop");
    let elapsed = started.elapsed();
    // 600 periods = 60 s of robot time; about 20 ms on an idle machine.
    assert!(elapsed < Duration::from_secs(2), "{elapsed:?}");
    eprintln!("60 s lock-step session over TCP: {elapsed:?}");

    // Each row's command is what `send` returned: the rounded command the robot acted on.
    let over_tcp: Vec<_> = rows
        .iter()
        .map(|(o, v, w)| (o.t, *v, *w, o.v, o.w))
        .collect();
    let mut direct = SimRobot::new(&profile, &sim).expect("sim");
    let mut directly = Vec::with_capacity(n + 1);
    let mut s = direct.sample();
    for row in &over_tcp {
        directly.push((s.t, row.1, row.2, s.v, s.w));
        s = direct.step(row.1, row.2);
    }
    let theta_tcp = least_squares(&recording("<pioneer over tcp>", &over_tcp));
    let theta_direct = least_squares(&recording("<simulator>", &directly));
    for i in 0..6 {
        assert!(
            (theta_tcp[i] - theta_direct[i]).abs() <= 1e-9 * (1.0 + theta_direct[i].abs()),
            "θ{}: {} over TCP, {} direct",
            i + 1,
            theta_tcp[i],
            theta_direct[i]
        );
    }
    eprintln!("θ̂ = {theta_tcp:?}");
    // And the experiment identifies the robot: the dominant parameters within 10 %.
    for i in [0, 1, 3, 5] {
        let rel = (theta_tcp[i] - profile.theta[i]).abs() / profile.theta[i].abs();
        assert!(
            rel < 0.1,
            "θ{}: {} vs true {}",
            i + 1,
            theta_tcp[i],
            profile.theta[i]
        );
    }
}

#[test]
fn a_long_straight_run_crosses_the_15_bit_position_wrap() {
    let profile = RobotProfile::pioneer3dx();
    let sim = SimSettings::default();
    let server =
        ArcosServer::spawn(profile.clone(), sim.clone(), Pacing::LockStep).expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    let mut direct = SimRobot::new(&profile, &sim).expect("sim");
    let mut crossed = false;
    for _ in 0..300 {
        let (v, w) = robot.send(1.2, 0.0).expect("send");
        assert_eq!((v, w), (1.2, 0.0));
        let o = robot.read().expect("read");
        let s = direct.step(v, w);
        assert!(
            (o.pose.x - s.x).abs() <= 0.5e-3 + 1e-9,
            "x {} vs {}",
            o.pose.x,
            s.x
        );
        assert!((o.pose.y - s.y).abs() <= 0.5e-3 + 1e-9);
        crossed |= robot.last_sip().xpos < 1000 && o.pose.x > 30.0;
    }
    // 30 s at 1.2 m/s: beyond 32.768 m, where the firmware's XPOS counter starts again at 0.
    let x = robot.last_report().pose.x;
    assert!(x > 33.0 && crossed, "x = {x}");
}

#[test]
fn read_without_send_pulses_and_the_command_holds() {
    let profile = RobotProfile::pioneer3dx();
    let sim = SimSettings::default();
    let server =
        ArcosServer::spawn(profile.clone(), sim.clone(), Pacing::LockStep).expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    let mut direct = SimRobot::new(&profile, &sim).expect("sim");
    let (vq, wq) = robot.send(0.25, -0.3).expect("send");
    assert_eq!((vq, wq), on_the_wire(0.25, -0.3));
    // 0.3 rad/s = 17.19°/s goes out as 17°/s.
    assert_eq!(wq, -17f64.to_radians());
    for k in 1..=5 {
        // Only the first read follows a send; the others send a PULSE, which also advances the
        // lock-step server, and the robot acts on the command `send` returned all along.
        let o = robot.read().expect("read");
        let s = direct.step(vq, wq);
        assert_eq!(o.t, k as f64 * 0.1);
        assert!((o.v - s.v).abs() < 1e-9 && (o.w - s.w).abs() < 1e-9);
    }
    assert_eq!(robot.command(), (250, -17));
}

/// With `max_v`/`max_w` set, `send` returns the clamped and rounded command, and that is what
/// the robot acts on.
#[test]
fn send_returns_the_clamped_command_the_robot_acts_on() {
    let profile = RobotProfile::pioneer3dx();
    let sim = SimSettings::default();
    let server =
        ArcosServer::spawn(profile.clone(), sim.clone(), Pacing::LockStep).expect("server");
    let settings = PioneerSettings {
        max_v: Some(0.5),
        max_w: Some(1.0),
        ..settings_for(&server)
    };
    let mut robot = Pioneer::connect(&settings).expect("connect");
    let mut direct = SimRobot::new(&profile, &sim).expect("sim");
    // 0.9 m/s → 0.5 m/s = 500 mm/s; −3 rad/s → −1 rad/s = −57.3°/s → −57°/s.
    let (v, w) = robot.send(0.9, -3.0).expect("send");
    assert_eq!((v, w), (0.5, -57f64.to_radians()));
    assert_eq!(robot.command(), (500, -57));
    for _ in 0..20 {
        let o = robot.read().expect("read");
        let s = direct.step(v, w);
        assert!((o.v - s.v).abs() <= 0.5e-3 + 1e-12, "{} vs {}", o.v, s.v);
        assert!((o.w - s.w).abs() <= 1e-3 / profile.track + 1e-12);
    }
    assert!(robot.last_report().v > 0.4, "{:?}", robot.last_report());
    // Not finite: refused, nothing sent.
    assert!(matches!(
        robot.send(f64::NAN, 0.0),
        Err(RobotError::Setting(_))
    ));
    assert_eq!(robot.command(), (500, -57));
    robot.stop().expect("stop");
}

#[test]
fn realtime_pacing_sends_a_sip_every_period() {
    let server = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings::default(),
        Pacing::RealTime,
    )
    .expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    let started = Instant::now();
    let mut o = robot.last_report();
    for k in 1..=8 {
        robot.send(0.3, 0.0).expect("send");
        o = robot.read().expect("read");
        assert_eq!(o.t, k as f64 * 0.1);
    }
    let elapsed = started.elapsed();
    // Eight SIPs at 100 ms: 0.7–0.8 s after the first.
    assert!(
        elapsed >= Duration::from_millis(600) && elapsed < Duration::from_secs(3),
        "{elapsed:?}"
    );
    assert!(o.v > 0.1, "{o:?}");
    robot.stop().expect("stop");
}

#[test]
fn stop_sends_close_and_later_calls_fail() {
    let server = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings::default(),
        Pacing::LockStep,
    )
    .expect("server");
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    robot.send(0.2, 0.1).expect("send");
    robot.read().expect("read");
    robot.stop().expect("stop");
    assert_eq!(robot.command(), (0, 0));
    let m = protocol_message(robot.read());
    assert!(m.contains("stop()"), "{m}");
    assert!(matches!(robot.send(0.1, 0.0), Err(RobotError::Protocol(_))));
    robot.stop().expect("a second stop does nothing");
    // The server ended that session and serves the next client.
    let mut again = Pioneer::connect(&settings_for(&server)).expect("reconnect");
    again.send(0.1, 0.0).expect("send");
    assert_eq!(again.read().expect("read").t, 0.1);
}

#[test]
fn the_server_survives_clients_that_hang_up() {
    let server = ArcosServer::spawn(
        RobotProfile::pioneer3dx(),
        SimSettings::default(),
        Pacing::LockStep,
    )
    .expect("server");
    // Hangs up in the middle of the handshake.
    {
        let mut raw = TcpStream::connect(server.addr()).expect("raw");
        raw.write_all(&Packet::command(cmd::SYNC0).to_bytes())
            .expect("write");
    }
    // Opens a session and hangs up without CLOSE.
    {
        let mut raw = TcpStream::connect(server.addr()).expect("raw");
        for id in [cmd::SYNC0, cmd::SYNC1, cmd::SYNC2, cmd::OPEN] {
            raw.write_all(&Packet::command(id).to_bytes())
                .expect("write");
        }
        raw.set_read_timeout(Some(Duration::from_secs(5)))
            .expect("timeout");
        let mut buf = [0u8; 64];
        let n = raw.read(&mut buf).expect("the SYNC0 echo at least");
        assert!(n >= 6);
    }
    // A client dropped without stop() (its Drop sends VEL 0, RVEL 0, CLOSE).
    {
        let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
        robot.send(0.5, 0.0).expect("send");
        robot.read().expect("read");
    }
    // The next client gets a fresh robot at rest at the origin.
    let mut robot = Pioneer::connect(&settings_for(&server)).expect("connect");
    let first = robot.last_report();
    assert_eq!((first.pose.x, first.pose.y, first.v), (0.0, 0.0, 0.0));
    robot.send(0.1, 0.0).expect("send");
    robot.read().expect("read");
    drop(robot);
    let started = Instant::now();
    server.shutdown();
    assert!(started.elapsed() < Duration::from_secs(1));
}

// ---------------------------------------------------------------------------------------------
// Failures

#[test]
fn connecting_to_a_closed_port_is_an_io_error_naming_the_address() {
    let port = {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        listener.local_addr().expect("addr").port()
    };
    let settings = PioneerSettings {
        port: format!("tcp://127.0.0.1:{port}"),
        timeout_s: 1.0,
        ..PioneerSettings::default()
    };
    match Pioneer::connect(&settings) {
        Err(RobotError::Io { what, source }) => {
            assert!(what.contains(&format!("127.0.0.1:{port}")), "{what}");
            assert!(what.contains("connecting"), "{what}");
            assert_eq!(source.kind(), std::io::ErrorKind::ConnectionRefused);
        }
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn a_missing_serial_device_is_an_io_error_naming_the_path() {
    let settings = PioneerSettings {
        port: "/dev/wheelid-no-such-tty".into(),
        ..PioneerSettings::default()
    };
    match Pioneer::connect(&settings) {
        Err(RobotError::Io { what, .. }) => {
            assert!(what.contains("/dev/wheelid-no-such-tty"), "{what}");
            assert!(what.contains("serial port at 9600 baud"), "{what}");
        }
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn a_server_that_never_answers_gives_a_timeout_not_a_hang() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr");
    let (done, wait) = mpsc::channel::<()>();
    let silent = thread::spawn(move || {
        let (_stream, _) = listener.accept().expect("accept");
        let _ = wait.recv_timeout(Duration::from_secs(10));
    });
    let started = Instant::now();
    let result = Pioneer::connect(&PioneerSettings {
        port: format!("tcp://{addr}"),
        timeout_s: 0.3,
        ..PioneerSettings::default()
    });
    let elapsed = started.elapsed();
    done.send(()).expect("release");
    silent.join().expect("join");
    match result {
        Err(RobotError::Timeout(m)) => {
            assert!(m.contains(&addr.to_string()) && m.contains("SYNC0"), "{m}");
        }
        other => panic!("expected a timeout, got {other:?}"),
    }
    assert!(elapsed < Duration::from_secs(2), "{elapsed:?}");
}

/// A hand-made robot for the failure cases. If `stale`, it is still open from an earlier client
/// and streams SIPs every 10 ms until it gets a CLOSE. Then it answers the handshake, sends one
/// SIP on OPEN, and after that the next `script` entry for each RVEL or PULSE (nothing once the
/// script is done) until the client hangs up.
fn fake_robot(listener: TcpListener, mut stale: bool, script: Vec<Vec<u8>>) {
    let (mut stream, _) = listener.accept().expect("accept");
    stream
        .set_read_timeout(Some(Duration::from_millis(10)))
        .expect("timeout");
    let sip = Sip::default().to_packet().expect("sip").to_bytes();
    let echo = Packet::new(cmd::SYNC2, b"fake\0Pioneer\0p3dx-sh\0".to_vec())
        .expect("echo")
        .to_bytes();
    let mut script = script.into_iter();
    let mut reader = PacketReader::new();
    let mut buf = [0u8; 256];
    let (mut synced, mut open) = (false, false);
    loop {
        if stale && stream.write_all(&sip).is_err() {
            return;
        }
        match stream.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => reader.push(&buf[..n]),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => return,
        }
        while let Ok(Some(p)) = reader.next_packet() {
            let reply = match (stale, synced, open, p.id()) {
                (true, _, _, cmd::CLOSE) => {
                    stale = false;
                    None
                }
                (true, ..) => None,
                (false, false, _, cmd::SYNC2) => {
                    synced = true;
                    Some(echo.clone())
                }
                (false, false, _, id) => Some(Packet::command(id).to_bytes()),
                (false, true, false, cmd::OPEN) => {
                    open = true;
                    Some(sip.clone())
                }
                (false, true, true, cmd::RVEL | cmd::PULSE) => script.next(),
                _ => None,
            };
            if let Some(bytes) = reply
                && stream.write_all(&bytes).is_err()
            {
                return;
            }
        }
    }
}

fn fake_settings(addr: std::net::SocketAddr) -> PioneerSettings {
    PioneerSettings {
        port: format!("tcp://{addr}"),
        period_s: 0.05,
        timeout_s: 0.5,
        ..PioneerSettings::default()
    }
}

#[test]
fn a_robot_that_stops_sending_sips_gives_a_timeout() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr");
    let fake = thread::spawn(move || fake_robot(listener, false, Vec::new()));
    let mut robot = Pioneer::connect(&fake_settings(addr)).expect("connect");
    assert_eq!(robot.identity().name, "fake");
    robot.send(0.1, 0.0).expect("send");
    let started = Instant::now();
    match robot.read() {
        Err(RobotError::Timeout(m)) => {
            assert!(
                m.contains(&addr.to_string()) && m.contains("waiting for a SIP"),
                "{m}"
            )
        }
        other => panic!("expected a timeout, got {other:?}"),
    }
    assert!(started.elapsed() < Duration::from_secs(2));
    drop(robot);
    fake.join().expect("join");
}

#[test]
fn a_corrupted_sip_is_a_protocol_error_and_the_next_sip_still_reads() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr");
    let moving = Sip {
        moving: true,
        l_vel: 100,
        r_vel: 100,
        ..Sip::default()
    };
    let good = moving.to_packet().expect("sip").to_bytes();
    let mut corrupted = good.clone();
    let n = corrupted.len();
    corrupted[n - 2] ^= 0x10;
    let script = vec![corrupted, good];
    let fake = thread::spawn(move || fake_robot(listener, false, script));
    let mut robot = Pioneer::connect(&fake_settings(addr)).expect("connect");
    robot.send(0.1, 0.0).expect("send");
    let m = protocol_message(robot.read());
    assert!(
        m.contains(&addr.to_string()) && m.contains("checksum"),
        "{m}"
    );
    // The next read (a PULSE goes out) gets the next SIP. Only whole, valid SIPs count for the
    // timestamp: the lost one does not.
    let o = robot.read().expect("read");
    assert_eq!((o.t, o.v, o.w), (0.05, 0.1, 0.0));
    drop(robot);
    fake.join().expect("join");
}

#[test]
fn a_robot_left_open_by_an_earlier_client_is_closed_and_synced_again() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr");
    let fake = thread::spawn(move || fake_robot(listener, true, Vec::new()));
    let robot = Pioneer::connect(&fake_settings(addr)).expect("connect");
    assert_eq!(robot.identity().subclass, "p3dx-sh");
    drop(robot);
    fake.join().expect("join");
}

#[test]
fn settings_read_from_toml_with_defaults_and_reject_unknown_fields() {
    let s: PioneerSettings = toml::from_str(
        r#"
        port = "/dev/ttyUSB0"
        baud = 38400
        max_v = 0.8
        "#,
    )
    .expect("toml");
    assert_eq!(s.port, "/dev/ttyUSB0");
    assert_eq!(s.baud, 38400);
    assert_eq!(s.max_v, Some(0.8));
    assert_eq!((s.period_s, s.timeout_s, s.track_m), (0.1, 2.0, 0.34));
    assert_eq!(s.max_w, None);
    assert!(toml::from_str::<PioneerSettings>("prot = \"/dev/ttyS0\"").is_err());
}
