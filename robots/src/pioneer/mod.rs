//! The Pioneer 3-DX backend: the ARCOS client–server protocol over a serial line or TCP.
//!
//! * [`arcos`] — the packet codec: frames and checksum, client commands, the standard SIP,
//!   and the conversions from its integer fields to SI units ([`arcos::Odometer`]).
//! * [`Pioneer`] ([`client`]) — the [`Robot`](wheelid_core::Robot) backend:
//!   `Pioneer::connect(&PioneerSettings)` (which reads SIP 0, the report at t = 0), then
//!   `send(v_ref, w_ref)` / `read()` once per SIP.
//! * [`ArcosServer`] ([`server`]) — an ARCOS-speaking server on top of the simulator, for
//!   tests and demos, as MobileSim is for ARIA; [`Pacing::LockStep`] makes a session
//!   deterministic and as fast as the CPU allows.
//!
//! # Protocol source
//!
//! *Pioneer 3 Operations Manual* (MobileRobots Inc., version 3, 2006), chapter 6 "ARCOS":
//! "Client-Server Communication Packet Protocols" (header 0xFA 0xFB, byte count, checksum),
//! "Client Commands" (SYNC0/1/2, PULSE 0, OPEN 1, CLOSE 2, ENABLE 4, VEL 11, RVEL 21;
//! argument types 0x3B, 0x1B, 0x2B), "Server Information Packets" (the standard SIP). Each
//! rule was cross-checked against ARIA (the reference client: `ArRobotPacket.cpp`,
//! `ArRobotPacketSender.cpp`, `ArCommands.h`, `ArRobot::asyncConnectHandler` for the
//! handshake, `ArRobot::processMotorPacket` for the SIP, `params/p3dx-sh.p` for the
//! conversion factors of ARCOS firmware) and MobileSim (the reference server:
//! `EmulatePioneer.cc`), with ROS `p2os` as a third reading of the checksum and SIP layout.
//!
//! # Session
//!
//! ```text
//! client                          server
//! SYNC0 ───────────────────────▶  echo SYNC0
//! SYNC1 ───────────────────────▶  echo SYNC1
//! SYNC2 ───────────────────────▶  echo SYNC2 + "name\0class\0subclass\0"
//! OPEN, ENABLE 1 ──────────────▶  SIP 0, SIP 1, … every SipCycle (100 ms)
//! VEL mm/s, RVEL °/s (or PULSE) ▶ …
//! VEL 0, RVEL 0, CLOSE ────────▶  stops
//! ```
//!
//! # Conversions
//!
//! * Commands: VEL = round(1000 v_ref) mm/s, RVEL = round(ω_ref·180/π) °/s, each clamped to
//!   ±32767 ([`quantize_command`]): the protocol's resolution is 1 mm/s and 1 °/s
//!   (0.01745 rad/s). `send` returns the command as the robot will act on it,
//!   (VEL/1000 m/s, RVEL·π/180 rad/s), the one to record.
//! * Reports: v = (L VEL + R VEL)/2 mm/s, ω = (R VEL − L VEL)/d with d =
//!   [`PioneerSettings::track_m`] — the wheel velocities of every ARCOS version rather than the
//!   ROTVEL field (0.1 °/s) of later ones; x, y from the 15-bit XPOS, YPOS counters \[mm\],
//!   unwrapped; heading from THPOS in units of 2π/4096 rad, unwrapped.
//! * Time: reports counted × period, t = k · `period_s` for the k-th SIP after the first
//!   (deterministic, not the host's clock; see [`Pioneer`]).

pub mod arcos;
pub mod client;
pub mod server;

pub use arcos::{Odometer, Packet, PacketReader, Sip};
pub use client::{Link, Pioneer, PioneerSettings, RobotIdentity, quantize_command};
pub use server::{ArcosServer, Pacing, ServerHandle};
