//! The ARCOS packet codec: frames, client commands, the standard SIP, and the conversions from
//! its integer fields to SI units.
//!
//! Source: *Pioneer 3 Operations Manual* (MobileRobots Inc., version 3, 2006), chapter 6
//! "ARCOS", sections "Client-Server Communication Packet Protocols" (frame and checksum),
//! "Client Commands" (the command table) and "Server Information Packets" (the standard SIP
//! table). Cross-checked line by line against ARIA (`ArRobotPacket::calcCheckSum` and
//! `finalizePacket`, `ArRobotPacketSender::comInt`, `ArCommands.h`,
//! `ArRobot::processMotorPacket`, `params/p3dx-sh.p`), MobileSim (`EmulatePioneer.cc`,
//! `SIPGenerator::getPacket`, the server side) and ROS `p2os` (`packet.cpp`, `sip.cpp`).
//!
//! # Frame (both directions)
//!
//! ```text
//! 0xFA 0xFB | count | id | data … | checksum (high byte, low byte)
//!             count = number of bytes after itself = 1 (id) + data + 2 (checksum) ≤ 255
//! ```
//!
//! `id` is the command number (client → server) or the packet type (server → client). Integers
//! in `data` are 2 bytes, least significant byte first. The checksum runs over `id` and `data`:
//! the sum of consecutive byte pairs taken as `(first << 8) | second`, modulo 2¹⁶; an odd last
//! byte is XORed into the sum ([`checksum`]).
//!
//! # Client commands
//!
//! A command is its number alone, or its number and one argument. An integer argument is an
//! argument-type byte — [`ARG_INT`] (0x3B) for a value ≥ 0, [`ARG_NINT`] (0x1B) for a negative
//! one — followed by the 2-byte absolute value; a string argument is [`ARG_STR`] (0x2B), a
//! length byte and the characters ([`Packet::command_int`], [`Packet::command_str`]). The
//! numbers used here are in [`cmd`].
//!
//! # The standard SIP (type 0x32 motors stopped, 0x33 moving)
//!
//! | field | type | unit and conversion (ARCOS firmware, ARIA `p3dx-sh.p`) |
//! |---|---|---|
//! | XPOS, YPOS | u16, 15 bits | mm (DistConvFactor 1.0); a wrapping counter mod 2¹⁵ |
//! | THPOS | i16 | 2π/4096 rad = 0.001534 rad (AngleConvFactor) |
//! | L VEL, R VEL | i16 | mm/s (VelConvFactor 1.0) |
//! | BATTERY | u8 | 0.1 V |
//! | STALL AND BUMPERS | u16 | bit 0 left wheel stalled, bits 1–7 bumpers, bit 8 right wheel stalled, bits 9–15 bumpers |
//! | CONTROL | i16 | heading servo setpoint, angle units |
//! | FLAGS | u16 | bit 0 motors enabled, bits 1–4 sonar arrays, 5 STOP, … |
//! | COMPASS | u8 | 2° |
//! | SONAR COUNT, then (NUMBER u8, RANGE u16 mm) × count | | |
//! | GRIP_STATE, ANPORT, ANALOG, DIGIN, DIGOUT | u8 each | |
//! | BATTERYX10 | u16 | 0.1 V |
//! | CHARGESTATE | u8 | |
//! | ROTVEL | i16 | 0.1 °/s |
//! | FAULTFLAGS | u16 | |
//!
//! Fields after the sonar readings were appended by later firmware versions (ARIA reads each
//! only if bytes remain; so does [`Sip::decode`]); anything after FAULTFLAGS is skipped by
//! length.
//!
//! # Conversions ([`Odometer`])
//!
//! * v = (L VEL + R VEL)/2 · 10⁻³ m/s; ω = (R VEL − L VEL)/d · 10⁻³ rad/s with the track d \[m\]
//!   (the firmware's own ROTVEL, in 0.1 °/s, is decoded but not used: it is missing on older
//!   firmware, and the wheel form is the one the simulator's encoder model follows).
//! * x, y: the first SIP's counters read as signed 15-bit numbers (mm), then the shortest
//!   signed difference of successive counters mod 2¹⁵ is accumulated ([`position_delta`]; ARIA
//!   assumes less than 4096 mm per cycle, this form allows up to 16 m).
//! * heading: THPOS × 2π/4096, unwrapped by accumulating the shortest difference mod 4096
//!   ([`angle_delta`]), so it keeps counting past ±π.

use std::f64::consts::PI;

use wheelid_core::{Pose, RobotError};

/// The two header bytes that start every packet.
pub const HEADER: [u8; 2] = [0xFA, 0xFB];

/// Argument type: a positive (≥ 0) 2-byte integer follows.
pub const ARG_INT: u8 = 0x3B;
/// Argument type: the absolute value of a negative 2-byte integer follows.
pub const ARG_NINT: u8 = 0x1B;
/// Argument type: a length byte and that many characters follow.
pub const ARG_STR: u8 = 0x2B;

/// Client command numbers (Pioneer 3 Operations Manual, table of ARCOS client commands;
/// ARIA `ArCommands.h`).
pub mod cmd {
    /// Handshake step 0 (before the connection is open; the same number as PULSE).
    pub const SYNC0: u8 = 0;
    /// Handshake step 1 (the same number as OPEN).
    pub const SYNC1: u8 = 1;
    /// Handshake step 2 (the same number as CLOSE); the server's echo carries the robot's
    /// name, class and subclass.
    pub const SYNC2: u8 = 2;
    /// Keep-alive: resets the server's watchdog. No argument.
    pub const PULSE: u8 = 0;
    /// Starts the controller and the SIP stream. No argument.
    pub const OPEN: u8 = 1;
    /// Closes the connection: stops the robot and the SIP stream. No argument.
    pub const CLOSE: u8 = 2;
    /// Enables (1) or disables (0) the motors.
    pub const ENABLE: u8 = 4;
    /// Translational velocity setpoint [mm/s], signed.
    pub const VEL: u8 = 11;
    /// Rotational velocity setpoint [°/s], signed.
    pub const RVEL: u8 = 21;
}

/// Packet type of a standard SIP while the motors are stopped.
pub const SIP_STOPPED: u8 = 0x32;
/// Packet type of a standard SIP while the robot is moving.
pub const SIP_MOVING: u8 = 0x33;

/// Whether a packet type is a standard SIP (0x32 or 0x33; ARIA tests `(id & 0xF0) == 0x30`
/// to sort them from the other packet types, and 0x32/0x33 to parse them).
pub fn is_standard_sip(id: u8) -> bool {
    id == SIP_STOPPED || id == SIP_MOVING
}

/// FLAGS bit 0: the motors are enabled.
pub const FLAG_MOTORS_ENABLED: u16 = 1;

/// One angle unit of THPOS and CONTROL \[rad\]: 2π/4096 (ARIA's AngleConvFactor 0.001534).
pub const ANGLE_UNIT_RAD: f64 = 2.0 * PI / 4096.0;

/// The position counters XPOS, YPOS count millimetres modulo 2¹⁵.
pub const POSITION_MODULUS: i64 = 1 << 15;

/// The angle counter THPOS counts 2π/4096 units modulo 4096.
pub const ANGLE_MODULUS: i64 = 4096;

fn protocol(msg: impl Into<String>) -> RobotError {
    RobotError::Protocol(msg.into())
}

/// The ARCOS checksum of `body` (the bytes from the packet's `id` through its last data byte):
/// the byte pairs summed as big-endian 16-bit words modulo 2¹⁶, an odd last byte XORed in.
/// Sent high byte first.
pub fn checksum(body: &[u8]) -> u16 {
    let mut pairs = body.chunks_exact(2);
    let mut sum = 0u16;
    for pair in &mut pairs {
        sum = sum.wrapping_add(u16::from_be_bytes([pair[0], pair[1]]));
    }
    if let [last] = pairs.remainder() {
        sum ^= u16::from(*last);
    }
    sum
}

/// One ARCOS packet: its `id` (command number or packet type) and the data bytes between the
/// `id` and the checksum.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    id: u8,
    data: Vec<u8>,
}

impl Packet {
    /// Largest data length: the count byte (≤ 255) also covers the id and the checksum. (The
    /// manual asks clients to stay under 200 bytes per packet.)
    pub const MAX_DATA: usize = 255 - 3;

    /// A packet of type `id` with `data`.
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if `data` is longer than [`Packet::MAX_DATA`].
    pub fn new(id: u8, data: Vec<u8>) -> Result<Self, RobotError> {
        if data.len() > Self::MAX_DATA {
            return Err(protocol(format!(
                "packet 0x{id:02X}: {} data bytes, at most {} fit the byte count",
                data.len(),
                Self::MAX_DATA
            )));
        }
        Ok(Self { id, data })
    }

    /// The command `number` without an argument (SYNC0–2, PULSE, OPEN, CLOSE).
    pub fn command(number: u8) -> Self {
        Self {
            id: number,
            data: Vec::new(),
        }
    }

    /// The command `number` with the integer argument `value`: [`ARG_INT`] and `value` for
    /// value ≥ 0, [`ARG_NINT`] and |value| otherwise, 2 bytes LSB first (ARIA `comInt`). The
    /// magnitude is clamped to 65535, the largest the 2 bytes hold.
    pub fn command_int(number: u8, value: i32) -> Self {
        let kind = if value >= 0 { ARG_INT } else { ARG_NINT };
        let magnitude = u16::try_from(value.unsigned_abs()).unwrap_or(u16::MAX);
        let [lo, hi] = magnitude.to_le_bytes();
        Self {
            id: number,
            data: vec![kind, lo, hi],
        }
    }

    /// The command `number` with a string argument: [`ARG_STR`], the length byte, the bytes
    /// (ARIA `comStr`).
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if the string does not fit one packet.
    pub fn command_str(number: u8, text: &[u8]) -> Result<Self, RobotError> {
        let len = u8::try_from(text.len())
            .ok()
            .filter(|&n| usize::from(n) + 2 <= Self::MAX_DATA)
            .ok_or_else(|| {
                protocol(format!(
                    "command {number}: a {}-byte string does not fit one packet",
                    text.len()
                ))
            })?;
        let mut data = Vec::with_capacity(text.len() + 2);
        data.push(ARG_STR);
        data.push(len);
        data.extend_from_slice(text);
        Ok(Self { id: number, data })
    }

    /// The command number or packet type.
    pub fn id(&self) -> u8 {
        self.id
    }

    /// The data bytes between the id and the checksum.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The packet's bytes on the wire: header, count, id, data, checksum (high byte first).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.data.len() + 6);
        out.extend_from_slice(&HEADER);
        // `new` and the constructors keep data.len() ≤ MAX_DATA, so the count fits a byte.
        out.push(u8::try_from(self.data.len() + 3).unwrap_or(u8::MAX));
        out.push(self.id);
        out.extend_from_slice(&self.data);
        let sum = checksum(&out[3..]);
        out.extend_from_slice(&sum.to_be_bytes());
        out
    }

    /// Decodes exactly one packet from `frame` (header through checksum).
    ///
    /// # Errors
    /// [`RobotError::Protocol`] naming the fault: a bad header, a byte count below 3, a frame
    /// shorter (truncated) or longer than its byte count says, or a checksum mismatch.
    pub fn from_frame(frame: &[u8]) -> Result<Self, RobotError> {
        let [h0, h1, count, ..] = *frame else {
            return Err(protocol(format!(
                "truncated packet: {} bytes, a packet has at least 6",
                frame.len()
            )));
        };
        if [h0, h1] != HEADER {
            return Err(protocol(format!(
                "bad header {h0:02X} {h1:02X} (expected FA FB)"
            )));
        }
        if count < 3 {
            return Err(protocol(format!(
                "bad byte count {count}: it must cover the id and the 2-byte checksum (≥ 3)"
            )));
        }
        let needed = 3 + usize::from(count);
        if frame.len() < needed {
            return Err(protocol(format!(
                "truncated packet: byte count {count} needs {needed} bytes, got {}",
                frame.len()
            )));
        }
        if frame.len() > needed {
            return Err(protocol(format!(
                "{} bytes after the end of a packet of byte count {count}",
                frame.len() - needed
            )));
        }
        let body = &frame[3..needed - 2];
        let sent = u16::from_be_bytes([frame[needed - 2], frame[needed - 1]]);
        let computed = checksum(body);
        if sent != computed {
            return Err(protocol(format!(
                "bad checksum in packet type 0x{:02X}: sent 0x{sent:04X}, computed 0x{computed:04X}",
                body[0]
            )));
        }
        Ok(Self {
            id: body[0],
            data: body[1..].to_vec(),
        })
    }

    /// The integer argument of a client command: `None` without an argument.
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if the argument is not an [`ARG_INT`]/[`ARG_NINT`] integer.
    pub fn int_arg(&self) -> Result<Option<i32>, RobotError> {
        match *self.data.as_slice() {
            [] => Ok(None),
            [ARG_INT, lo, hi] => Ok(Some(i32::from(u16::from_le_bytes([lo, hi])))),
            [ARG_NINT, lo, hi] => Ok(Some(-i32::from(u16::from_le_bytes([lo, hi])))),
            _ => Err(protocol(format!(
                "command {}: expected no argument or an integer argument, got {:02X?}",
                self.id, self.data
            ))),
        }
    }

    /// The NUL-terminated strings in the data (the SYNC2 echo carries name, class and
    /// subclass this way); a last string without its NUL counts too.
    pub fn strings(&self) -> Vec<String> {
        let data = self.data.strip_suffix(&[0]).unwrap_or(&self.data);
        if data.is_empty() {
            return Vec::new();
        }
        data.split(|&b| b == 0)
            .map(|s| String::from_utf8_lossy(s).into_owned())
            .collect()
    }
}

/// Cuts a byte stream into [`Packet`]s: bytes go in with [`PacketReader::push`] as they arrive,
/// whole packets come out of [`PacketReader::next_packet`].
#[derive(Debug, Default, Clone)]
pub struct PacketReader {
    buf: Vec<u8>,
}

impl PacketReader {
    /// An empty reader.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes received but not yet returned as packets.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// The next whole packet, or `None` until more bytes arrive.
    ///
    /// # Errors
    /// [`RobotError::Protocol`] for bytes that do not start with the header, a byte count
    /// below 3, or a checksum mismatch. The offending bytes are dropped up to the next header,
    /// so the following call resynchronizes.
    pub fn next_packet(&mut self) -> Result<Option<Packet>, RobotError> {
        let [h0, h1, ..] = *self.buf else {
            if self.buf.first().is_some_and(|&b| b != HEADER[0]) {
                let dropped = self.skip_to_header(1);
                return Err(protocol(format!(
                    "bad header: dropped {dropped} byte(s) before FA FB"
                )));
            }
            return Ok(None);
        };
        if [h0, h1] != HEADER {
            let dropped = self.skip_to_header(1);
            return Err(protocol(format!(
                "bad header {h0:02X} {h1:02X} (expected FA FB): dropped {dropped} byte(s)"
            )));
        }
        let Some(&count) = self.buf.get(2) else {
            return Ok(None);
        };
        let needed = 3 + usize::from(count);
        if count < 3 {
            self.skip_to_header(2);
            return Err(protocol(format!(
                "bad byte count {count}: it must cover the id and the 2-byte checksum (≥ 3)"
            )));
        }
        if self.buf.len() < needed {
            return Ok(None);
        }
        match Packet::from_frame(&self.buf[..needed]) {
            Ok(packet) => {
                self.buf.drain(..needed);
                Ok(Some(packet))
            }
            Err(e) => {
                self.skip_to_header(2);
                Err(e)
            }
        }
    }

    /// Drops bytes up to the next header at or after `from` (keeping a trailing 0xFA that may
    /// start one); returns how many were dropped.
    fn skip_to_header(&mut self, from: usize) -> usize {
        let from = from.min(self.buf.len());
        let next = self.buf[from..]
            .windows(2)
            .position(|w| w == HEADER)
            .map(|p| from + p)
            .unwrap_or_else(|| {
                if self.buf.last() == Some(&HEADER[0]) {
                    self.buf.len() - 1
                } else {
                    self.buf.len()
                }
            })
            .max(from);
        self.buf.drain(..next);
        next
    }
}

/// One sonar reading of a SIP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SonarReading {
    /// Sonar disc number (0–31).
    pub number: u8,
    /// Range \[mm\] (RangeConvFactor 1.0).
    pub range: u16,
}

/// The user I/O bytes of a SIP (present since early ARCOS versions).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SipIo {
    /// Gripper state byte.
    pub grip_state: u8,
    /// Selected analog port.
    pub anport: u8,
    /// Analog input on that port (0–255 = 0–5 V).
    pub analog: u8,
    /// Digital inputs.
    pub digin: u8,
    /// Digital outputs.
    pub digout: u8,
}

/// A standard SIP, field by field in the firmware's integer units (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Sip {
    /// Packet type 0x33 (moving) rather than 0x32 (motors stopped).
    pub moving: bool,
    /// XPOS: x counter \[mm\] mod 2¹⁵.
    pub xpos: u16,
    /// YPOS: y counter \[mm\] mod 2¹⁵.
    pub ypos: u16,
    /// THPOS: heading [2π/4096 rad].
    pub thpos: i16,
    /// L VEL: left wheel velocity [mm/s].
    pub l_vel: i16,
    /// R VEL: right wheel velocity [mm/s].
    pub r_vel: i16,
    /// BATTERY: battery voltage [0.1 V].
    pub battery: u8,
    /// STALL AND BUMPERS: bit 0 left stall, bit 8 right stall, bits 1–7 and 9–15 bumpers.
    pub stall_bumpers: u16,
    /// CONTROL: heading servo setpoint [2π/4096 rad].
    pub control: i16,
    /// FLAGS: bit 0 motors enabled ([`FLAG_MOTORS_ENABLED`]), bits 1–4 sonar arrays, …
    pub flags: u16,
    /// COMPASS: heading of the compass accessory [2°].
    pub compass: u8,
    /// New sonar readings.
    pub sonars: Vec<SonarReading>,
    /// GRIP_STATE … DIGOUT, when the firmware sends them.
    pub io: Option<SipIo>,
    /// BATTERYX10: battery voltage [0.1 V], when sent.
    pub battery_x10: Option<u16>,
    /// CHARGESTATE, when sent.
    pub charge_state: Option<u8>,
    /// ROTVEL: rotational velocity [0.1 °/s], when sent.
    pub rot_vel: Option<i16>,
    /// FAULTFLAGS, when sent.
    pub fault_flags: Option<u16>,
}

/// Reads little-endian fields off a SIP's data, naming the field that runs out.
struct Fields<'a> {
    data: &'a [u8],
    at: usize,
}

impl Fields<'_> {
    fn take<const N: usize>(&mut self, field: &str) -> Result<[u8; N], RobotError> {
        let bytes = self
            .data
            .get(self.at..self.at + N)
            .and_then(|s| <[u8; N]>::try_from(s).ok())
            .ok_or_else(|| {
                protocol(format!(
                    "SIP truncated: {} data bytes end inside {field}",
                    self.data.len()
                ))
            })?;
        self.at += N;
        Ok(bytes)
    }
    fn u8(&mut self, field: &str) -> Result<u8, RobotError> {
        Ok(self.take::<1>(field)?[0])
    }
    fn u16(&mut self, field: &str) -> Result<u16, RobotError> {
        Ok(u16::from_le_bytes(self.take(field)?))
    }
    fn i16(&mut self, field: &str) -> Result<i16, RobotError> {
        Ok(i16::from_le_bytes(self.take(field)?))
    }
    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.at)
    }
}

impl Sip {
    /// Decodes a standard SIP packet (type 0x32 or 0x33).
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if the packet is another type or ends inside a field.
    pub fn decode(packet: &Packet) -> Result<Self, RobotError> {
        if !is_standard_sip(packet.id()) {
            return Err(protocol(format!(
                "packet type 0x{:02X} is not a standard SIP (0x32/0x33)",
                packet.id()
            )));
        }
        let mut f = Fields {
            data: packet.data(),
            at: 0,
        };
        let mut sip = Sip {
            moving: packet.id() == SIP_MOVING,
            xpos: f.u16("XPOS")? & 0x7FFF,
            ypos: f.u16("YPOS")? & 0x7FFF,
            thpos: f.i16("THPOS")?,
            l_vel: f.i16("L VEL")?,
            r_vel: f.i16("R VEL")?,
            battery: f.u8("BATTERY")?,
            stall_bumpers: f.u16("STALL AND BUMPERS")?,
            control: f.i16("CONTROL")?,
            flags: f.u16("FLAGS")?,
            compass: f.u8("COMPASS")?,
            ..Sip::default()
        };
        let count = f.u8("SONAR COUNT")?;
        for _ in 0..count {
            sip.sonars.push(SonarReading {
                number: f.u8("sonar NUMBER")?,
                range: f.u16("sonar RANGE")?,
            });
        }
        if f.remaining() > 0 {
            sip.io = Some(SipIo {
                grip_state: f.u8("GRIP_STATE")?,
                anport: f.u8("ANPORT")?,
                analog: f.u8("ANALOG")?,
                digin: f.u8("DIGIN")?,
                digout: f.u8("DIGOUT")?,
            });
        }
        if f.remaining() > 0 {
            sip.battery_x10 = Some(f.u16("BATTERYX10")?);
        }
        if f.remaining() > 0 {
            sip.charge_state = Some(f.u8("CHARGESTATE")?);
        }
        if f.remaining() > 0 {
            sip.rot_vel = Some(f.i16("ROTVEL")?);
        }
        if f.remaining() > 0 {
            sip.fault_flags = Some(f.u16("FAULTFLAGS")?);
        }
        // Later fields (LATVEL, temperature, state of charge, …) are skipped by length.
        Ok(sip)
    }

    /// Encodes the SIP as a packet: the optional tail up to its last present field, earlier
    /// absent ones as zeros.
    ///
    /// # Errors
    /// [`RobotError::Protocol`] if the sonar readings do not fit one packet.
    pub fn to_packet(&self) -> Result<Packet, RobotError> {
        let mut d = Vec::with_capacity(40 + 3 * self.sonars.len());
        d.extend_from_slice(&(self.xpos & 0x7FFF).to_le_bytes());
        d.extend_from_slice(&(self.ypos & 0x7FFF).to_le_bytes());
        d.extend_from_slice(&self.thpos.to_le_bytes());
        d.extend_from_slice(&self.l_vel.to_le_bytes());
        d.extend_from_slice(&self.r_vel.to_le_bytes());
        d.push(self.battery);
        d.extend_from_slice(&self.stall_bumpers.to_le_bytes());
        d.extend_from_slice(&self.control.to_le_bytes());
        d.extend_from_slice(&self.flags.to_le_bytes());
        d.push(self.compass);
        let count = u8::try_from(self.sonars.len())
            .map_err(|_| protocol(format!("{} sonar readings in one SIP", self.sonars.len())))?;
        d.push(count);
        for s in &self.sonars {
            d.push(s.number);
            d.extend_from_slice(&s.range.to_le_bytes());
        }
        let tail = [
            self.io.is_some(),
            self.battery_x10.is_some(),
            self.charge_state.is_some(),
            self.rot_vel.is_some(),
            self.fault_flags.is_some(),
        ];
        let last = tail.iter().rposition(|&present| present);
        if let Some(last) = last {
            let io = self.io.unwrap_or_default();
            d.extend_from_slice(&[io.grip_state, io.anport, io.analog, io.digin, io.digout]);
            if last >= 1 {
                d.extend_from_slice(&self.battery_x10.unwrap_or(0).to_le_bytes());
            }
            if last >= 2 {
                d.push(self.charge_state.unwrap_or(0));
            }
            if last >= 3 {
                d.extend_from_slice(&self.rot_vel.unwrap_or(0).to_le_bytes());
            }
            if last >= 4 {
                d.extend_from_slice(&self.fault_flags.unwrap_or(0).to_le_bytes());
            }
        }
        let id = if self.moving { SIP_MOVING } else { SIP_STOPPED };
        Packet::new(id, d)
    }

    /// Whether FLAGS says the motors are enabled.
    pub fn motors_enabled(&self) -> bool {
        self.flags & FLAG_MOTORS_ENABLED != 0
    }

    /// Whether the left (bit 0) or right (bit 8) wheel is stalled.
    pub fn stalled(&self) -> bool {
        self.stall_bumpers & 0x0101 != 0
    }

    /// Forward and angular velocity (v [m/s], ω [rad/s]) from the wheel velocities and the
    /// track `track_m` \[m\]: v = (L + R)/2, ω = (R − L)/d.
    pub fn velocities(&self, track_m: f64) -> (f64, f64) {
        let (l, r) = (f64::from(self.l_vel), f64::from(self.r_vel));
        ((l + r) / 2000.0, (r - l) / (1000.0 * track_m))
    }
}

/// The shortest signed difference `to − from` of two 15-bit position counters \[counts\], in
/// [−2¹⁴, 2¹⁴).
pub fn position_delta(from: u16, to: u16) -> i64 {
    let d = i64::from(to & 0x7FFF) - i64::from(from & 0x7FFF);
    (d + POSITION_MODULUS / 2).rem_euclid(POSITION_MODULUS) - POSITION_MODULUS / 2
}

/// The shortest signed difference `to − from` of two headings [angle units], in [−2048, 2048).
pub fn angle_delta(from: i16, to: i16) -> i64 {
    let d = i64::from(to) - i64::from(from);
    (d + ANGLE_MODULUS / 2).rem_euclid(ANGLE_MODULUS) - ANGLE_MODULUS / 2
}

/// The firmware's 15-bit counter for a position of `mm` millimetres.
pub fn position_counter(mm: i64) -> u16 {
    // rem_euclid keeps the value in [0, 2¹⁵), so the conversion cannot fail.
    u16::try_from(mm.rem_euclid(POSITION_MODULUS)).unwrap_or(0)
}

/// THPOS for a heading of `rad` radians: the nearest angle unit, wrapped to [−2048, 2048).
pub fn angle_units(rad: f64) -> i16 {
    let units = (rad / ANGLE_UNIT_RAD).round() as i64;
    let wrapped = (units + ANGLE_MODULUS / 2).rem_euclid(ANGLE_MODULUS) - ANGLE_MODULUS / 2;
    i16::try_from(wrapped).unwrap_or(0)
}

/// Turns successive standard SIPs into velocities and an unwrapped pose (see the module docs).
/// Positions and heading are accumulated in integer counts, so the pose is exact and
/// reproducible.
#[derive(Debug, Clone)]
pub struct Odometer {
    track_m: f64,
    last: Option<(u16, u16, i16)>,
    x_mm: i64,
    y_mm: i64,
    heading_units: i64,
}

impl Odometer {
    /// An odometer for a robot of track `track_m` \[m\] (used for ω only).
    pub fn new(track_m: f64) -> Self {
        Self {
            track_m,
            last: None,
            x_mm: 0,
            y_mm: 0,
            heading_units: 0,
        }
    }

    /// Takes the next SIP; returns (v [m/s], ω [rad/s], pose). The first SIP sets the pose
    /// from its counters read as signed 15-bit numbers; the following ones add the shortest
    /// differences.
    pub fn update(&mut self, sip: &Sip) -> (f64, f64, Pose) {
        match self.last {
            None => {
                let signed = |c: u16| {
                    let c = i64::from(c & 0x7FFF);
                    if c >= POSITION_MODULUS / 2 {
                        c - POSITION_MODULUS
                    } else {
                        c
                    }
                };
                self.x_mm = signed(sip.xpos);
                self.y_mm = signed(sip.ypos);
                self.heading_units = i64::from(sip.thpos);
            }
            Some((x, y, th)) => {
                self.x_mm += position_delta(x, sip.xpos);
                self.y_mm += position_delta(y, sip.ypos);
                self.heading_units += angle_delta(th, sip.thpos);
            }
        }
        self.last = Some((sip.xpos, sip.ypos, sip.thpos));
        let (v, w) = sip.velocities(self.track_m);
        (v, w, self.pose())
    }

    /// The pose after the last SIP: x, y \[m\], heading \[rad\], unwrapped.
    pub fn pose(&self) -> Pose {
        Pose {
            x: self.x_mm as f64 / 1000.0,
            y: self.y_mm as f64 / 1000.0,
            heading: self.heading_units as f64 * ANGLE_UNIT_RAD,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_sums_big_endian_pairs_and_xors_an_odd_byte() {
        // By hand: 0x043B + 0x0100 = 0x053B.
        assert_eq!(checksum(&[0x04, 0x3B, 0x01, 0x00]), 0x053B);
        // 0x3201 ^ 0x02.
        assert_eq!(checksum(&[0x32, 0x01, 0x02]), 0x3203);
        // 0x0B3B + 0xFF7F = 0x10ABA, kept mod 2¹⁶.
        assert_eq!(checksum(&[0x0B, 0x3B, 0xFF, 0x7F]), 0x0ABA);
        assert_eq!(checksum(&[]), 0);
    }

    #[test]
    fn int_arguments_carry_their_sign_in_the_type_byte() {
        let p = Packet::command_int(cmd::RVEL, -30);
        assert_eq!(p.data(), &[ARG_NINT, 30, 0]);
        assert_eq!(p.int_arg().expect("int"), Some(-30));
        let p = Packet::command_int(cmd::VEL, 70_000);
        assert_eq!(p.int_arg().expect("int"), Some(65535));
        assert_eq!(Packet::command(cmd::PULSE).int_arg().expect("none"), None);
        let s = Packet::command_str(3, b"ab").expect("fits");
        assert_eq!(s.data(), &[ARG_STR, 2, b'a', b'b']);
        assert!(matches!(s.int_arg(), Err(RobotError::Protocol(_))));
    }

    #[test]
    fn reader_splits_a_stream_and_resynchronizes_after_garbage() {
        let a = Packet::command_int(cmd::VEL, 100).to_bytes();
        let b = Packet::command(cmd::PULSE).to_bytes();
        let mut r = PacketReader::new();
        r.push(&[0x00, 0x11]);
        r.push(&a[..4]);
        assert!(
            matches!(r.next_packet(), Err(RobotError::Protocol(m)) if m.contains("bad header"))
        );
        assert_eq!(r.next_packet().expect("partial"), None);
        r.push(&a[4..]);
        r.push(&b);
        assert_eq!(r.next_packet().expect("a").map(|p| p.id()), Some(cmd::VEL));
        assert_eq!(
            r.next_packet().expect("b").map(|p| p.id()),
            Some(cmd::PULSE)
        );
        assert_eq!(r.next_packet().expect("empty"), None);
        assert_eq!(r.buffered(), 0);

        // A corrupted checksum is reported once; the next packet still comes through.
        let mut bad = a.clone();
        let n = bad.len();
        bad[n - 1] ^= 0xFF;
        r.push(&bad);
        r.push(&b);
        assert!(matches!(r.next_packet(), Err(RobotError::Protocol(m)) if m.contains("checksum")));
        assert_eq!(
            r.next_packet().expect("b").map(|p| p.id()),
            Some(cmd::PULSE)
        );
    }

    #[test]
    fn counters_wrap_and_differences_take_the_short_way() {
        assert_eq!(position_counter(32_767), 0x7FFF);
        assert_eq!(position_counter(32_768), 0);
        assert_eq!(position_counter(-1), 0x7FFF);
        assert_eq!(position_delta(0x7FF0, 0x0010), 0x20);
        assert_eq!(position_delta(0x0010, 0x7FF0), -0x20);
        assert_eq!(angle_units(PI), -2048);
        assert_eq!(angle_units(-PI / 2.0), -1024);
        assert_eq!(angle_delta(2047, -2048), 1);
        assert_eq!(angle_delta(-2048, 2047), -1);
    }
}
