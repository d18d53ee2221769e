//! The replay backend: CDR bytes against hand-computed layouts, the quaternion's yaw on
//! closed-form cases, Recording → MCAP → Replay round trips, the zero-order-hold alignment of
//! commands on hand-built bags, CSV replay, and the errors.

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::{Path, PathBuf};

use approx::assert_abs_diff_eq;
use mcap::records::MessageHeader;
use wheelid_core::{Recording, Robot, RobotError};
use wheelid_robots::replay::ros::{
    self, Header, Odometry, Point, Pose, PoseWithCovariance, Quaternion, Time, Twist, TwistStamped,
    TwistWithCovariance,
};
use wheelid_robots::replay::{
    BagTopics, CommandType, Replay, ReplayFormat, ReplaySettings, TimeSource, read_mcap, write_mcap,
};
use wheelid_robots::{Excitation, RobotProfile, SimSettings, simulate_recording};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// An epoch for hand-built bags: 2023-11-14T22:13:20Z in ns.
const EPOCH_NS: u64 = 1_700_000_000_000_000_000;

/// Little-endian bytes written by hand, with XCDR1 alignment counted from after the 4-byte
/// encapsulation header.
struct Le(Vec<u8>);

impl Le {
    fn new() -> Self {
        Le(vec![0x00, 0x01, 0x00, 0x00])
    }
    fn pad_to(&mut self, align: usize) -> &mut Self {
        while !(self.0.len() - 4).is_multiple_of(align) {
            self.0.push(0);
        }
        self
    }
    fn u32(&mut self, x: u32) -> &mut Self {
        self.pad_to(4).0.extend(x.to_le_bytes());
        self
    }
    fn i32(&mut self, x: i32) -> &mut Self {
        self.pad_to(4).0.extend(x.to_le_bytes());
        self
    }
    fn f64(&mut self, x: f64) -> &mut Self {
        self.pad_to(8).0.extend(x.to_le_bytes());
        self
    }
    fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend(s.as_bytes());
        self.0.push(0);
        self
    }
}

fn odometry_msg(ns: i64, x: f64, y: f64, yaw: f64, v: f64, w: f64) -> Odometry {
    Odometry {
        header: Header {
            stamp: Time::from_nanos(ns).expect("in range"),
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point { x, y, z: 0.0 },
                orientation: Quaternion::from_yaw(yaw),
            },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance {
            twist: Twist::planar(v, w),
            covariance: [0.0; 36],
        },
    }
}

/// One message of a hand-built bag: topic, log time \[ns\], payload.
struct Raw {
    topic: &'static str,
    log_ns: u64,
    data: Vec<u8>,
}

/// Writes `messages` in the given file order with the mcap crate directly (not `write_mcap`).
fn hand_built_bag(path: &Path, command_type: CommandType, messages: &[Raw]) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create"));
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(file)
        .expect("writer");
    let odom = w
        .add_schema(
            "nav_msgs/msg/Odometry",
            "ros2msg",
            ros::odometry_definition().as_bytes(),
        )
        .expect("schema");
    let (name, text) = match command_type {
        CommandType::Twist => ("geometry_msgs/msg/Twist", ros::twist_definition()),
        CommandType::TwistStamped => (
            "geometry_msgs/msg/TwistStamped",
            ros::twist_stamped_definition(),
        ),
    };
    let cmd = w
        .add_schema(name, "ros2msg", text.as_bytes())
        .expect("schema");
    let meta = BTreeMap::new();
    let odom = w.add_channel(odom, "/odom", "cdr", &meta).expect("channel");
    let cmd = w
        .add_channel(cmd, "/cmd_vel", "cdr", &meta)
        .expect("channel");
    for (i, m) in messages.iter().enumerate() {
        let header = MessageHeader {
            channel_id: if m.topic == "/odom" { odom } else { cmd },
            sequence: i as u32,
            log_time: m.log_ns,
            publish_time: m.log_ns,
        };
        w.write_to_known_channel(&header, &m.data).expect("write");
    }
    w.finish().expect("finish");
}

fn settings(path: &Path) -> ReplaySettings {
    ReplaySettings::new(path)
}

fn error_text(r: Result<impl std::fmt::Debug, RobotError>) -> (RobotError, String) {
    let e = r.expect_err("must fail");
    let s = e.to_string();
    (e, s)
}

// ---------------------------------------------------------------------------------------------
// CDR and the messages
// ---------------------------------------------------------------------------------------------

#[test]
fn twist_stamped_cdr_is_byte_exact() {
    let msg = TwistStamped {
        header: Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "ab".into(),
        },
        twist: Twist::planar(1.0, 0.5),
    };
    #[rustfmt::skip]
    let expected: Vec<u8> = vec![
        0x00, 0x01, 0x00, 0x00,             // encapsulation: CDR little endian
        0x01, 0x00, 0x00, 0x00,             // @0  stamp.sec = 1 (int32)
        0x02, 0x00, 0x00, 0x00,             // @4  stamp.nanosec = 2 (uint32)
        0x03, 0x00, 0x00, 0x00,             // @8  frame_id length 3, the NUL included
        b'a', b'b', 0x00,                   // @12 "ab" NUL
        0x00,                               // @15 pad: the next float64 sits at 16
        0, 0, 0, 0, 0, 0, 0xf0, 0x3f,       // @16 linear.x = 1.0
        0, 0, 0, 0, 0, 0, 0, 0,             // @24 linear.y
        0, 0, 0, 0, 0, 0, 0, 0,             // @32 linear.z
        0, 0, 0, 0, 0, 0, 0, 0,             // @40 angular.x
        0, 0, 0, 0, 0, 0, 0, 0,             // @48 angular.y
        0, 0, 0, 0, 0, 0, 0xe0, 0x3f,       // @56 angular.z = 0.5
    ];
    let bytes = ros::to_cdr(&msg).expect("encodes");
    assert_eq!(bytes, expected);
    // The same message serialised by the Python `rosbags` 0.11.9 (`serialize_cdr`).
    let rosbags = "0001000001000000020000000300000061620000000000000000f03f\
                   0000000000000000000000000000000000000000000000000000000000000000\
                   000000000000e03f";
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(hex, rosbags);
    let back: TwistStamped = ros::from_cdr(&bytes).expect("decodes");
    assert_eq!(back, msg);
}

#[test]
fn odometry_cdr_matches_the_hand_computed_layout() {
    let mut pose_cov = [0.0; 36];
    pose_cov[0] = 0.25;
    pose_cov[35] = -2.0;
    let mut twist_cov = [0.0; 36];
    twist_cov[7] = 1.5;
    let msg = Odometry {
        header: Header {
            stamp: Time {
                sec: 12,
                nanosec: 345,
            },
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point {
                    x: 1.5,
                    y: -2.0,
                    z: 0.0,
                },
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.6,
                    w: 0.8,
                },
            },
            covariance: pose_cov,
        },
        twist: TwistWithCovariance {
            twist: Twist::planar(0.4, -0.3),
            covariance: twist_cov,
        },
    };
    let mut e = Le::new();
    e.i32(12).u32(345).string("odom"); // ends at 17
    e.string("base_link"); // length at 20 (3 pad bytes), text 24..34
    for x in [1.5, -2.0, 0.0, 0.0, 0.0, 0.6, 0.8] {
        e.f64(x); // first at 40 (6 pad bytes)
    }
    for x in pose_cov {
        e.f64(x);
    }
    for x in [0.4, 0.0, 0.0, 0.0, 0.0, -0.3] {
        e.f64(x);
    }
    for x in twist_cov {
        e.f64(x);
    }
    let expected = e.0;
    // 4 + 40 + 7·8 + 36·8 + 6·8 + 36·8 = 724 bytes, as `rosbags` writes this message.
    assert_eq!(expected.len(), 724);
    assert_eq!(&expected[24..28], &[10, 0, 0, 0]); // child_frame_id length at body offset 20
    assert_eq!(&expected[38..44], &[0; 6]); // padding before position.x
    let bytes = ros::to_cdr(&msg).expect("encodes");
    assert_eq!(bytes, expected);
    let back: Odometry = ros::from_cdr(&bytes).expect("decodes");
    assert_eq!(back, msg);
    // Trailing padding (as DDS writers append) is ignored.
    let mut padded = bytes.clone();
    padded.extend([0, 0, 0]);
    assert_eq!(ros::from_cdr::<Odometry>(&padded).expect("decodes"), msg);
}

#[test]
fn big_endian_cdr_decodes_and_other_encapsulations_are_refused() {
    let mut bytes = vec![0x00, 0x00, 0x00, 0x00]; // CDR big endian
    for x in [0.25, 0.0, 0.0, 0.0, 0.0, -1.5] {
        bytes.extend(f64::to_be_bytes(x));
    }
    let t: Twist = ros::from_cdr(&bytes).expect("decodes");
    assert_eq!(t, Twist::planar(0.25, -1.5));
    assert!(matches!(
        ros::from_cdr::<Twist>(&[0, 1, 0]),
        Err(ros::CdrError::TooShort(3))
    ));
    bytes[1] = 0x07; // XCDR2 little endian: other alignment rules
    assert!(matches!(
        ros::from_cdr::<Twist>(&bytes),
        Err(ros::CdrError::Encapsulation(0x00, 0x07))
    ));
    bytes[1] = 0x01;
    bytes.truncate(20); // too short for six float64
    assert!(matches!(
        ros::from_cdr::<Twist>(&bytes),
        Err(ros::CdrError::Decode(_))
    ));
}

#[test]
fn time_splits_nanoseconds() {
    let t = Time::from_nanos(1_700_000_000_123_456_789).expect("in range");
    assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
    assert_eq!(t.nanos(), 1_700_000_000_123_456_789);
    let t = Time::from_nanos(-1).expect("in range");
    assert_eq!((t.sec, t.nanosec), (-1, 999_999_999));
    assert!(Time::from_nanos(i64::from(i32::MAX) * 1_000_000_000 + 1_000_000_000).is_none());
}

#[test]
fn yaw_of_closed_form_quaternions() {
    let h = 0.5_f64.sqrt();
    let q = |x, y, z, w| Quaternion { x, y, z, w };
    assert_eq!(q(0.0, 0.0, 0.0, 1.0).yaw(), 0.0);
    assert_abs_diff_eq!(q(0.0, 0.0, h, h).yaw(), FRAC_PI_2, epsilon = 1e-15);
    assert_abs_diff_eq!(q(0.0, 0.0, -h, h).yaw(), -FRAC_PI_2, epsilon = 1e-15);
    assert_abs_diff_eq!(q(0.0, 0.0, 1.0, 0.0).yaw(), PI, epsilon = 1e-15);
    // 60°: (0, 0, sin 30°, cos 30°) = (0, 0, 1/2, √3/2), also scaled by 2 (not unit).
    let (half, c) = (0.5, 3.0_f64.sqrt() / 2.0);
    assert_abs_diff_eq!(q(0.0, 0.0, half, c).yaw(), PI / 3.0, epsilon = 1e-15);
    assert_abs_diff_eq!(q(0.0, 0.0, 1.0, 2.0 * c).yaw(), PI / 3.0, epsilon = 1e-15);
    // Yaw ψ then roll r (z-y-x Euler): q = q_z(ψ) ⊗ q_x(r) = (c_ψ s_r, s_ψ s_r, s_ψ c_r, c_ψ c_r);
    // its yaw is still ψ.
    let (psi, r) = (0.7_f64, 0.4_f64);
    let (sp, cp) = (0.5 * psi).sin_cos();
    let (sr, cr) = (0.5 * r).sin_cos();
    assert_abs_diff_eq!(
        q(cp * sr, sp * sr, sp * cr, cp * cr).yaw(),
        psi,
        epsilon = 1e-15
    );
    // from_yaw is its inverse on (−π, π].
    for yaw in [-3.0, -1.0, 0.0, 0.3, 2.5, PI] {
        assert_abs_diff_eq!(Quaternion::from_yaw(yaw).yaw(), yaw, epsilon = 1e-15);
    }
}

#[test]
fn schemas_hold_the_definitions_with_their_dependencies() {
    let odom = ros::odometry_definition();
    assert!(odom.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
    let sep = format!("{}\n", "=".repeat(80));
    for dep in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3",
    ] {
        assert!(odom.contains(&format!("{sep}MSG: {dep}\n")), "{dep}");
    }
    assert!(odom.contains("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
    assert_eq!(
        ros::twist_definition(),
        format!(
            "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n{sep}\
             MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
        )
    );
    assert!(ros::twist_stamped_definition().starts_with("std_msgs/Header header\n"));
}

// ---------------------------------------------------------------------------------------------
// Round trips through write_mcap
// ---------------------------------------------------------------------------------------------

/// A simulated Pioneer drive: encoder noise, non-uniform sampling jitter if the simulator has
/// it, and a heading that winds past 2π (ω_ref ≈ 0.75 rad/s for 20 s).
fn simulated() -> Recording {
    let settings = SimSettings {
        duration_s: 20.0,
        ..SimSettings::default()
    };
    simulate_recording(
        &RobotProfile::pioneer3dx(),
        &Excitation::thesis_pioneer(),
        &settings,
    )
    .expect("simulates")
}

fn assert_same_drive(back: &Recording, rec: &Recording) {
    assert_eq!(back.len(), rec.len());
    let cols: [(&str, &[f64], &[f64]); 5] = [
        ("t", &back.t, &rec.t),
        ("v_ref", &back.v_ref, &rec.v_ref),
        ("w_ref", &back.w_ref, &rec.w_ref),
        ("v", &back.v, &rec.v),
        ("w", &back.w, &rec.w),
    ];
    for (name, a, b) in cols {
        for (k, (a, b)) in a.iter().zip(b).enumerate() {
            assert!((a - b).abs() <= 1e-9, "{name}[{k}]: {a} vs {b}");
        }
    }
    for (name, a, b) in [
        ("x", &back.x, &rec.x),
        ("y", &back.y, &rec.y),
        ("phi", &back.phi, &rec.phi),
    ] {
        let (a, b) = (a.as_ref().expect("pose"), b.as_ref().expect("pose"));
        for (k, (a, b)) in a.iter().zip(b).enumerate() {
            assert!((a - b).abs() <= 1e-9, "{name}[{k}]: {a} vs {b}");
        }
    }
}

#[test]
fn recording_round_trips_through_a_bag_with_twist_and_with_twist_stamped() {
    let rec = simulated();
    assert!(rec.t[0] == 0.0 && rec.len() > 150);
    let phi = rec.phi.as_ref().expect("pose");
    assert!(phi.iter().fold(0.0_f64, |m, p| m.max(p.abs())) > 2.0 * PI);
    let dir = tempfile::tempdir().expect("tmp");
    for command_type in [CommandType::Twist, CommandType::TwistStamped] {
        let path = dir.path().join(format!("{command_type:?}.mcap"));
        let topics = BagTopics {
            command_type,
            ..BagTopics::default()
        };
        write_mcap(&rec, &path, &topics).expect("writes");
        let mut robot = Replay::open(&settings(&path)).expect("opens");
        let back = robot.recording().clone();
        assert_same_drive(&back, &rec);
        assert_eq!(back.meta("command_type"), Some(command_type.schema_name()));
        assert_eq!(back.meta("command_hold"), Some("zoh"));
        // The writer's stamping convention comes back (encoder windows ending at t).
        assert_eq!(back.meta("velocity_sampling"), Some("window_average"));
        assert_eq!(back.timing(), rec.timing());
        assert_eq!(back.meta("robot"), Some("pioneer3dx"));
        assert_eq!(back.meta("odometry_frames"), Some("odom / base_link"));
        assert_eq!(back.meta("t0_ns"), Some("0"));
        assert_abs_diff_eq!(robot.period_s(), rec.sampling().dt_median, epsilon = 1e-9);
        // The robot interface replays the same numbers: read sample k, and `send` returns
        // the command logged with it (whatever is asked).
        let mut n = 0;
        loop {
            let o = match robot.read() {
                Ok(o) => o,
                Err(RobotError::Ended) => break,
                Err(e) => panic!("unexpected error {e}"),
            };
            let k = n;
            n += 1;
            assert_abs_diff_eq!(o.t, rec.t[k], epsilon = 1e-9);
            assert_abs_diff_eq!(o.pose.heading, phi[k], epsilon = 1e-9);
            let (vr, wr) = robot.send(-1.0, 7.0).expect("send");
            assert_abs_diff_eq!(vr, rec.v_ref[k], epsilon = 1e-12);
            assert_abs_diff_eq!(wr, rec.w_ref[k], epsilon = 1e-12);
        }
        assert_eq!(n, rec.len());
        assert_eq!(robot.sent().len(), rec.len());
    }
    // Stamped commands also read by their header stamps, which equal the log times here.
    let path = dir.path().join("TwistStamped.mcap");
    let s = ReplaySettings {
        time_source: TimeSource::HeaderStamp,
        ..settings(&path)
    };
    assert_same_drive(&s.load().expect("reads"), &rec);
}

#[test]
fn round_trip_keeps_times_relative_to_the_first_sample_and_zero_pose_without_pose() {
    let rec = Recording::new(
        "no_pose",
        vec![5.0, 5.1, 5.25, 5.3],
        vec![0.1, 0.2, 0.3, 0.4],
        vec![-1.0, 0.0, 1.0, 2.0],
        vec![0.5, 0.6, 0.7, 0.8],
        vec![0.01, 0.02, 0.03, 0.04],
    )
    .expect("valid");
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("b.mcap");
    write_mcap(&rec, &path, &BagTopics::default()).expect("writes");
    let back = read_mcap(&path, &BagTopics::default(), TimeSource::LogTime, None).expect("reads");
    for (a, b) in back.t.iter().zip(&rec.t) {
        assert_abs_diff_eq!(*a, b - 5.0, epsilon = 1e-9);
    }
    assert_eq!(back.w_ref, rec.w_ref);
    assert_eq!(back.x, Some(vec![0.0; 4]));
    assert_eq!(back.phi, Some(vec![0.0; 4]));
}

#[test]
fn write_is_atomic_and_names_the_file_on_failure() {
    let rec = simulated();
    let dir = tempfile::tempdir().expect("tmp");
    let missing = dir.path().join("no_such_dir").join("x.mcap");
    let (e, s) = error_text(write_mcap(&rec, &missing, &BagTopics::default()));
    assert!(matches!(e, RobotError::Io { .. }), "{e:?}");
    assert!(s.contains("no_such_dir"), "{s}");
    let ok = dir.path().join("x.mcap");
    write_mcap(&rec, &ok, &BagTopics::default()).expect("writes");
    let names: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .expect("ls")
        .map(|e| e.expect("entry").path())
        .collect();
    assert_eq!(names, vec![ok]);
    // An invalid recording is refused before anything is written.
    let mut bad = rec.clone();
    bad.v[3] = f64::NAN;
    let (e, s) = error_text(write_mcap(
        &bad,
        &dir.path().join("y.mcap"),
        &BagTopics::default(),
    ));
    assert!(
        matches!(e, RobotError::Protocol(_)) && s.contains("`v`, sample 3"),
        "{s}"
    );
    assert!(!dir.path().join("y.mcap").exists());
}

// ---------------------------------------------------------------------------------------------
// Zero-order hold on hand-built bags
// ---------------------------------------------------------------------------------------------

/// Odometry every 0.1 s from 0 to 0.9 s; commands at irregular times, one of them written out of
/// time order, two at the same instant, one exactly on a sample.
const ODOM_S: [f64; 10] = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9];
const COMMANDS: [(f64, f64, f64); 6] = [
    // (time [s], v_ref, ω_ref) in file order
    (0.05, 0.1, -0.1),
    (0.1, 0.2, -0.2),
    (0.1, 0.3, -0.3), // same instant, later in the file: this one holds
    (0.71, 0.6, -0.6),
    (0.33, 0.4, -0.4), // written after 0.71 but earlier in time
    (0.95, 0.9, -0.9), // after the last sample: never used
];

fn ns(s: f64) -> u64 {
    EPOCH_NS + (s * 1e9).round() as u64
}

/// The expected command at `t`, by brute force: the last command (in time, then file order) at
/// or before t, zero if none, zero if older than `timeout`.
fn expected_command(t: f64, timeout: Option<f64>) -> (f64, f64) {
    let mut best: Option<(f64, f64, f64)> = None;
    for &(tc, v, w) in &COMMANDS {
        if ns(tc) <= ns(t) && best.is_none_or(|(tb, _, _)| ns(tc) >= ns(tb)) {
            best = Some((tc, v, w));
        }
    }
    match best {
        Some((tc, v, w)) if timeout.is_none_or(|limit| t - tc <= limit + 1e-12) => (v, w),
        _ => (0.0, 0.0),
    }
}

/// A bag with Twist (or TwistStamped with stamps `stamp_shift_s` before the log times)
/// commands at COMMANDS and odometry at ODOM_S (odometry stamps also shifted).
fn zoh_bag(path: &Path, command_type: CommandType, stamp_shift_s: f64) {
    let mut messages = Vec::new();
    for (k, &t) in ODOM_S.iter().enumerate() {
        let stamp = ns(t) as i64 - (stamp_shift_s * 1e9).round() as i64;
        let msg = odometry_msg(stamp, 0.1 * k as f64, 0.0, 0.0, 0.5, 0.05 * k as f64);
        messages.push(Raw {
            topic: "/odom",
            log_ns: ns(t),
            data: ros::to_cdr(&msg).expect("encodes"),
        });
    }
    for &(t, v, w) in &COMMANDS {
        let twist = Twist::planar(v, w);
        let data = match command_type {
            CommandType::Twist => ros::to_cdr(&twist),
            CommandType::TwistStamped => ros::to_cdr(&TwistStamped {
                header: Header {
                    stamp: Time::from_nanos(ns(t) as i64 - (stamp_shift_s * 1e9).round() as i64)
                        .expect("in range"),
                    frame_id: "base_link".into(),
                },
                twist,
            }),
        };
        messages.push(Raw {
            topic: "/cmd_vel",
            log_ns: ns(t),
            data: data.expect("encodes"),
        });
    }
    hand_built_bag(path, command_type, &messages);
}

#[test]
fn commands_are_held_from_the_last_message_at_or_before_each_sample() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("zoh.mcap");
    zoh_bag(&path, CommandType::Twist, 0.0);
    let rec = read_mcap(&path, &BagTopics::default(), TimeSource::LogTime, None).expect("reads");
    assert_eq!(rec.len(), ODOM_S.len());
    // A bag not written by wheelid claims no stamping convention.
    assert_eq!(rec.timing(), None);
    assert_eq!(rec.meta("velocity_sampling"), None);
    assert_eq!(rec.meta("t0_ns"), Some("1700000000000000000"));
    assert_eq!(rec.meta("command_type"), Some("geometry_msgs/msg/Twist"));
    for (k, &t) in ODOM_S.iter().enumerate() {
        assert_abs_diff_eq!(rec.t[k], t, epsilon = 1e-9);
        assert_eq!(
            (rec.v_ref[k], rec.w_ref[k]),
            expected_command(t, None),
            "t = {t}"
        );
        assert_eq!(rec.v[k], 0.5);
        assert_abs_diff_eq!(rec.w[k], 0.05 * k as f64, epsilon = 1e-15);
    }
    // Spelled out: zero before the first command, the later of two equal-time commands, the
    // out-of-order command at 0.33 s from 0.4 s on.
    assert_eq!(
        rec.v_ref,
        vec![0.0, 0.3, 0.3, 0.3, 0.4, 0.4, 0.4, 0.4, 0.6, 0.6]
    );
}

#[test]
fn a_stale_command_counts_as_zero_after_the_timeout() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("zoh.mcap");
    zoh_bag(&path, CommandType::Twist, 0.0);
    let rec = read_mcap(
        &path,
        &BagTopics::default(),
        TimeSource::LogTime,
        Some(0.25),
    )
    .expect("reads");
    for (k, &t) in ODOM_S.iter().enumerate() {
        assert_eq!(
            (rec.v_ref[k], rec.w_ref[k]),
            expected_command(t, Some(0.25)),
            "t = {t}"
        );
    }
    // 0.6 s and 0.7 s: the command of 0.33 s is 0.27 s and 0.37 s old.
    assert_eq!(
        rec.v_ref,
        vec![0.0, 0.3, 0.3, 0.3, 0.4, 0.4, 0.0, 0.0, 0.6, 0.6]
    );
    assert_eq!(rec.meta("command_timeout_s"), Some("0.25"));
    let (e, _) = error_text(read_mcap(
        &path,
        &BagTopics::default(),
        TimeSource::LogTime,
        Some(0.0),
    ));
    assert!(matches!(e, RobotError::Setting(_)));
}

#[test]
fn twist_stamped_commands_align_by_log_time_or_by_header_stamp() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("stamped.mcap");
    // Every stamp 13 ms before its log time: the same alignment on either clock.
    zoh_bag(&path, CommandType::TwistStamped, 0.013);
    for time_source in [TimeSource::LogTime, TimeSource::HeaderStamp] {
        let rec = read_mcap(&path, &BagTopics::default(), time_source, None).expect("reads");
        assert_eq!(
            rec.meta("command_type"),
            Some("geometry_msgs/msg/TwistStamped")
        );
        assert_eq!(rec.meta("time_source"), Some(time_source.as_str()));
        let t0 = match time_source {
            TimeSource::LogTime => "1700000000000000000",
            TimeSource::HeaderStamp => "1699999999987000000",
        };
        assert_eq!(rec.meta("t0_ns"), Some(t0));
        for (k, &t) in ODOM_S.iter().enumerate() {
            assert_abs_diff_eq!(rec.t[k], t, epsilon = 1e-9);
            assert_eq!((rec.v_ref[k], rec.w_ref[k]), expected_command(t, None));
        }
    }
}

#[test]
fn header_stamps_that_differ_from_log_times_change_the_alignment() {
    // Commands stamped 60 ms before they were logged; odometry stamps equal to log times.
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("late.mcap");
    let mut messages = Vec::new();
    for &t in &ODOM_S {
        let msg = odometry_msg(ns(t) as i64, 0.0, 0.0, 0.0, 0.0, 0.0);
        messages.push(Raw {
            topic: "/odom",
            log_ns: ns(t),
            data: ros::to_cdr(&msg).expect("encodes"),
        });
    }
    let stamped = |t_log: f64, v: f64| TwistStamped {
        header: Header {
            stamp: Time::from_nanos(ns(t_log - 0.06) as i64).expect("in range"),
            frame_id: String::new(),
        },
        twist: Twist::planar(v, 0.0),
    };
    for (t_log, v) in [(0.25, 1.0), (0.45, 2.0)] {
        messages.push(Raw {
            topic: "/cmd_vel",
            log_ns: ns(t_log),
            data: ros::to_cdr(&stamped(t_log, v)).expect("encodes"),
        });
    }
    hand_built_bag(&path, CommandType::TwistStamped, &messages);
    let by_log = read_mcap(&path, &BagTopics::default(), TimeSource::LogTime, None).expect("ok");
    let by_stamp =
        read_mcap(&path, &BagTopics::default(), TimeSource::HeaderStamp, None).expect("ok");
    // Logged at 0.25 and 0.45 s, stamped 0.19 and 0.39 s.
    assert_eq!(
        by_log.v_ref,
        vec![0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 2.0]
    );
    assert_eq!(
        by_stamp.v_ref,
        vec![0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0]
    );
}

#[test]
fn heading_is_unwrapped_across_the_pi_cut() {
    // Yaw 3.0, 3.1 → π, then −3.1 (= 3.183… − 2π), −3.0: unwrapped it keeps increasing.
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("wrap.mcap");
    let yaws = [3.0, 3.1, 3.1 + 0.1 - 2.0 * PI, 3.0 + 0.4 - 2.0 * PI];
    let mut messages = Vec::new();
    for (k, yaw) in yaws.iter().enumerate() {
        let t = 0.1 * k as f64;
        messages.push(Raw {
            topic: "/odom",
            log_ns: ns(t),
            data: ros::to_cdr(&odometry_msg(0, 0.0, 0.0, *yaw, 0.0, 1.0)).expect("encodes"),
        });
    }
    messages.push(Raw {
        topic: "/cmd_vel",
        log_ns: ns(0.0),
        data: ros::to_cdr(&Twist::planar(0.0, 1.0)).expect("encodes"),
    });
    hand_built_bag(&path, CommandType::Twist, &messages);
    let rec = read_mcap(&path, &BagTopics::default(), TimeSource::LogTime, None).expect("reads");
    let phi = rec.phi.expect("pose");
    for (a, b) in phi.iter().zip([3.0, 3.1, 3.2, 3.4]) {
        assert_abs_diff_eq!(*a, b, epsilon = 1e-12);
    }
}

// ---------------------------------------------------------------------------------------------
// CSV replay and the settings
// ---------------------------------------------------------------------------------------------

const CSV: &str = "# robot: test\n\
                   t,v_ref,w_ref,v,w,x,y,phi\n\
                   0.0,0.4,0.75,0.0,0.0,0.0,0.0,0.0\n\
                   0.1,0.4,0.75,0.05,0.1,0.001,0.0,0.01\n\
                   0.2,0.3,-0.5,0.09,0.2,0.006,0.0001,0.03\n\
                   0.35,0.0,0.0,0.12,0.1,0.015,0.0003,0.05\n";

#[test]
fn csv_replay_reports_samples_in_order_then_ended() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("drive.csv");
    std::fs::write(&path, CSV).expect("write");
    let mut robot = Replay::open(&settings(&path)).expect("opens");
    assert_eq!(robot.name(), "replay");
    assert_abs_diff_eq!(robot.period_s(), 0.1, epsilon = 1e-12); // periods 0.1, 0.1, 0.15
    assert_eq!(robot.recording().meta("robot"), Some("test"));
    let expected = [
        (0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.4, 0.75)),
        (0.1, 0.05, 0.1, (0.001, 0.0, 0.01), (0.4, 0.75)),
        (0.2, 0.09, 0.2, (0.006, 0.0001, 0.03), (0.3, -0.5)),
        (0.35, 0.12, 0.1, (0.015, 0.0003, 0.05), (0.0, 0.0)),
    ];
    // Before the first read, `send` returns the first sample's logged command.
    assert_eq!(robot.send(8.0, -9.0).expect("send"), (0.4, 0.75));
    for (k, (t, v, w, (x, y, phi), logged)) in expected.into_iter().enumerate() {
        let o = robot.read().expect("sample");
        assert_eq!((o.t, o.v, o.w), (t, v, w));
        assert_eq!((o.pose.x, o.pose.y, o.pose.heading), (x, y, phi));
        // Whatever is sent, `send` returns the command logged with the sample just read.
        assert_eq!(robot.send(9.0 + k as f64, -9.0).expect("send"), logged);
    }
    assert!(matches!(robot.read(), Err(RobotError::Ended)));
    assert!(matches!(robot.read(), Err(RobotError::Ended)));
    // After the end, still the last sample's.
    assert_eq!(robot.send(13.0, -9.0).expect("send"), (0.0, 0.0));
    robot.stop().expect("stop");
    assert_eq!(
        robot.sent(),
        &[
            (8.0, -9.0),
            (9.0, -9.0),
            (10.0, -9.0),
            (11.0, -9.0),
            (12.0, -9.0),
            (13.0, -9.0),
            (0.0, 0.0)
        ]
    );
}

#[test]
fn a_replay_is_a_boxed_robot_and_reports_zero_pose_without_pose_columns() {
    let rec = Recording::new(
        "mem",
        vec![0.0, 0.02, 0.04],
        vec![1.0, 2.0, 3.0],
        vec![0.0; 3],
        vec![0.1, 0.2, 0.3],
        vec![0.0; 3],
    )
    .expect("valid");
    let mut robot: Box<dyn Robot> = Box::new(Replay::new(rec).expect("replay"));
    assert_abs_diff_eq!(robot.period_s(), 0.02, epsilon = 1e-15);
    assert_eq!(robot.send(0.0, 0.0).expect("send"), (1.0, 0.0)); // sample 0, before a read
    let o = robot.read().expect("sample");
    assert_eq!((o.pose.x, o.pose.y, o.pose.heading), (0.0, 0.0, 0.0));
    assert_eq!(robot.send(0.0, 0.0).expect("send"), (1.0, 0.0)); // sample 0, just read
    robot.read().expect("sample");
    assert_eq!(robot.send(0.0, 0.0).expect("send"), (2.0, 0.0)); // sample 1
    robot.stop().expect("stop");
}

#[test]
fn the_window_keeps_start_to_start_plus_duration() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("drive.csv");
    std::fs::write(&path, CSV).expect("write");
    let s = ReplaySettings {
        start_s: 0.1,
        duration_s: Some(0.1),
        ..settings(&path)
    };
    let rec = s.load().expect("reads");
    assert_eq!(rec.t, vec![0.1, 0.2]);
    assert_eq!(rec.phi, Some(vec![0.01, 0.03]));
    assert_eq!(rec.v_ref, vec![0.4, 0.3]);
    let empty = ReplaySettings {
        start_s: 5.0,
        ..settings(&path)
    };
    let (e, _) = error_text(empty.load());
    assert!(matches!(e, RobotError::Setting(_)));
    let bad = ReplaySettings {
        duration_s: Some(-1.0),
        ..settings(&path)
    };
    assert!(matches!(bad.load(), Err(RobotError::Setting(_))));
}

#[test]
fn settings_read_from_toml_with_defaults_and_refuse_unknown_keys() {
    let s: ReplaySettings = toml::from_str("path = \"run/drive.mcap\"").expect("parses");
    assert_eq!(s, ReplaySettings::new("run/drive.mcap"));
    assert_eq!(s.command_topic, "/cmd_vel");
    assert_eq!(s.odometry_topic, "/odom");
    assert_eq!(s.time_source, TimeSource::LogTime);
    assert_eq!(
        s.resolved_format().expect("from extension"),
        ReplayFormat::Mcap
    );
    let s: ReplaySettings = toml::from_str(
        "path = \"d.log\"\nformat = \"csv\"\ncommand_topic = \"/diff_drive/cmd_vel\"\n\
         odometry_topic = \"/diff_drive/odom\"\ntime_source = \"header_stamp\"\n\
         command_timeout_s = 0.5\nstart_s = 2.0\nduration_s = 30.0\n",
    )
    .expect("parses");
    assert_eq!(s.resolved_format().expect("set"), ReplayFormat::Csv);
    assert_eq!(s.time_source, TimeSource::HeaderStamp);
    assert_eq!(s.command_timeout_s, Some(0.5));
    let e = toml::from_str::<ReplaySettings>("path = \"a.mcap\"\nodom_topic = \"/x\"\n")
        .expect_err("unknown key");
    assert!(e.to_string().contains("odom_topic"), "{e}");
    let (e, s) = error_text(ReplaySettings::new("drive.bag").resolved_format());
    assert!(
        matches!(e, RobotError::Setting(_)) && s.contains("drive.bag"),
        "{s}"
    );
    // Settings write back to the same TOML.
    let text = toml::to_string(&ReplaySettings::new("a.csv")).expect("serialises");
    assert_eq!(
        toml::from_str::<ReplaySettings>(&text).expect("parses"),
        ReplaySettings::new("a.csv")
    );
}

#[test]
fn a_rosbag2_folder_with_one_mcap_opens_as_a_bag() {
    let dir = tempfile::tempdir().expect("tmp");
    let bag = dir.path().join("drive_bag");
    std::fs::create_dir(&bag).expect("mkdir");
    zoh_bag(&bag.join("drive_bag_0.mcap"), CommandType::Twist, 0.0);
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information: {}\n",
    )
    .expect("yaml");
    let robot = Replay::open(&settings(&bag)).expect("opens the folder");
    assert_eq!(robot.recording().len(), ODOM_S.len());
    zoh_bag(&bag.join("drive_bag_1.mcap"), CommandType::Twist, 0.0);
    let (e, s) = error_text(Replay::open(&settings(&bag)));
    assert!(
        matches!(e, RobotError::Setting(_)) && s.contains("found 2"),
        "{s}"
    );
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

#[test]
fn a_missing_file_is_an_io_error_naming_it() {
    let dir = tempfile::tempdir().expect("tmp");
    for name in ["nothing.csv", "nothing.mcap"] {
        let path = dir.path().join(name);
        let (e, s) = error_text(Replay::open(&settings(&path)));
        assert!(matches!(e, RobotError::Io { .. }), "{e:?}");
        assert!(s.contains(name), "{s}");
    }
}

#[test]
fn a_missing_topic_lists_the_topics_present() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("zoh.mcap");
    zoh_bag(&path, CommandType::Twist, 0.0);
    let s = ReplaySettings {
        odometry_topic: "/wheel/odometry".into(),
        ..settings(&path)
    };
    let (e, text) = error_text(Replay::open(&s));
    assert!(matches!(e, RobotError::Setting(_)), "{e:?}");
    assert!(
        text.contains("zoh.mcap") && text.contains("`/wheel/odometry`"),
        "{text}"
    );
    assert!(
        text.contains("/cmd_vel (geometry_msgs/msg/Twist), /odom (nav_msgs/msg/Odometry)"),
        "{text}"
    );
    let s = ReplaySettings {
        command_topic: "/cmd".into(),
        ..settings(&path)
    };
    let (_, text) = error_text(Replay::open(&s));
    assert!(
        text.contains("`/cmd`") && text.contains("/odom (nav_msgs"),
        "{text}"
    );
}

#[test]
fn a_topic_of_the_wrong_type_names_the_type_found() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("zoh.mcap");
    zoh_bag(&path, CommandType::Twist, 0.0);
    let s = ReplaySettings {
        odometry_topic: "/cmd_vel".into(),
        command_topic: "/odom".into(),
        ..settings(&path)
    };
    let (e, text) = error_text(Replay::open(&s));
    assert!(matches!(e, RobotError::Setting(_)), "{e:?}");
    assert!(text.contains("carries `"), "{text}");
    assert!(
        text.contains("`geometry_msgs/msg/Twist`, expected nav_msgs/msg/Odometry")
            || text.contains("`nav_msgs/msg/Odometry`, expected geometry_msgs"),
        "{text}"
    );
    // Twist commands have no stamp to time them by.
    let s = ReplaySettings {
        time_source: TimeSource::HeaderStamp,
        ..settings(&path)
    };
    let (e, text) = error_text(Replay::open(&s));
    assert!(
        matches!(e, RobotError::Setting(_)) && text.contains("header_stamp"),
        "{text}"
    );
}

#[test]
fn a_message_that_does_not_decode_names_topic_index_and_log_time() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("bad_msg.mcap");
    let mut messages = Vec::new();
    for (k, &t) in ODOM_S[..4].iter().enumerate() {
        let mut data = ros::to_cdr(&odometry_msg(0, 0.0, 0.0, 0.0, 0.0, 0.0)).expect("encodes");
        if k == 2 {
            data.truncate(100); // cut inside the pose covariance
        }
        messages.push(Raw {
            topic: "/odom",
            log_ns: ns(t),
            data,
        });
    }
    hand_built_bag(&path, CommandType::Twist, &messages);
    let (e, text) = error_text(Replay::open(&settings(&path)));
    assert!(matches!(e, RobotError::Protocol(_)), "{e:?}");
    for part in [
        "bad_msg.mcap",
        "`/odom`",
        "index 2",
        "log time 1700000000.200000000 s",
        "nav_msgs/msg/Odometry",
    ] {
        assert!(text.contains(part), "{part} in {text}");
    }
}

#[test]
fn truncated_or_corrupt_bags_are_errors_not_panics() {
    let dir = tempfile::tempdir().expect("tmp");
    let good = dir.path().join("good.mcap");
    write_mcap(&simulated(), &good, &BagTopics::default()).expect("writes");
    let bytes = std::fs::read(&good).expect("read");
    let path = dir.path().join("cut.mcap");
    // Every truncation loses at least the end magic.
    for len in (0..bytes.len()).step_by(97).chain([bytes.len() - 1]) {
        std::fs::write(&path, &bytes[..len]).expect("write");
        let r = Replay::open(&settings(&path));
        assert!(r.is_err(), "truncated to {len} of {} bytes", bytes.len());
    }
    // A flipped byte in the first chunk fails its CRC (or its decompression).
    let mut corrupt = bytes.clone();
    corrupt[200] ^= 0x55;
    std::fs::write(&path, &corrupt).expect("write");
    let (e, text) = error_text(Replay::open(&settings(&path)));
    assert!(matches!(e, RobotError::Protocol(_)), "{e:?}");
    assert!(
        text.contains("cut.mcap") && text.contains("not a valid MCAP"),
        "{text}"
    );
    // Flipped bytes anywhere: an error or a reading, never a panic.
    for at in (0..bytes.len()).step_by(61) {
        let mut c = bytes.clone();
        c[at] ^= 0xff;
        std::fs::write(&path, &c).expect("write");
        let _ = Replay::open(&settings(&path));
    }
    // A CSV is not a bag.
    std::fs::write(&path, CSV).expect("write");
    let (e, text) = error_text(Replay::open(&settings(&path)));
    assert!(
        matches!(e, RobotError::Protocol(_)) && text.contains("not a valid MCAP"),
        "{text}"
    );
}

#[test]
fn invalid_recordings_are_refused() {
    let mut rec = Recording::new(
        "r",
        vec![0.0, 0.1, 0.2],
        vec![0.0; 3],
        vec![0.0; 3],
        vec![0.0; 3],
        vec![0.0; 3],
    )
    .expect("valid");
    rec.phi = Some(vec![0.0; 2]);
    let (e, text) = error_text(Replay::new(rec.clone()));
    assert!(
        matches!(e, RobotError::Protocol(_)) && text.contains("`phi`"),
        "{text}"
    );
    rec.phi = None;
    rec.t[2] = 0.1;
    let (_, text) = error_text(Replay::new(rec.clone()));
    assert!(text.contains("does not increase at sample 2"), "{text}");
    let one = Recording::new("one", vec![0.0], vec![0.0], vec![0.0], vec![0.0], vec![0.0])
        .expect("valid");
    assert!(matches!(Replay::new(one), Err(RobotError::Setting(_))));
    // A bad CSV names its line and column.
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("bad.csv");
    std::fs::write(&path, "t,v_ref,w_ref,v,w\n0,1,2,3,4\n0.1,1,x,3,4\n").expect("write");
    let (e, text) = error_text(Replay::open(&settings(&path)));
    assert!(matches!(e, RobotError::Protocol(_)), "{e:?}");
    assert!(text.contains("bad.csv:3:3"), "{text}");
}

#[test]
fn two_odometry_messages_at_one_time_are_refused() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("dup.mcap");
    let mut messages = Vec::new();
    for t in [0.0, 0.1, 0.1] {
        messages.push(Raw {
            topic: "/odom",
            log_ns: ns(t),
            data: ros::to_cdr(&odometry_msg(0, 0.0, 0.0, 0.0, 0.0, 0.0)).expect("encodes"),
        });
    }
    messages.push(Raw {
        topic: "/cmd_vel",
        log_ns: ns(0.0),
        data: ros::to_cdr(&Twist::default()).expect("encodes"),
    });
    hand_built_bag(&path, CommandType::Twist, &messages);
    let (e, text) = error_text(Replay::open(&settings(&path)));
    assert!(matches!(e, RobotError::Protocol(_)), "{e:?}");
    assert!(
        text.contains("same time") && text.contains("/odom"),
        "{text}"
    );
}
