//! ROS 2 bags in MCAP: reading a drive out of one, and writing a recording as one.
//!
//! A rosbag2 MCAP file (MCAP spec, profile `ros2`) holds Schema records (name such as
//! `nav_msgs/msg/Odometry`, encoding `ros2msg`, data the `.msg` text with its dependencies),
//! Channel records (a topic, its schema, message encoding `cdr`, metadata
//! `offered_qos_profiles`) and Message records (channel, sequence, `log_time` and
//! `publish_time` in ns since the epoch, and the CDR payload of [`super::ros`]).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Cursor};
use std::path::Path;

use ::mcap::io::MessageReader;
use ::mcap::sans_io::LinearReaderOptions;
use serde::{Deserialize, Serialize};
use wheelid_core::{Recording, RobotError};

use super::ros::{self, Header, Odometry, Time, Twist, TwistStamped};
use super::{TimeSource, check_recording, core_error};

const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// The largest MCAP record read [bytes]: a corrupt length field fails instead of allocating.
const RECORD_LENGTH_LIMIT: usize = 512 << 20;
/// The frames of REP 105 that written odometry uses: the pose in `odom`, the twist in `base_link`.
const ODOM_FRAME: &str = "odom";
const BASE_FRAME: &str = "base_link";

/// The message type of the command topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandType {
    /// `geometry_msgs/msg/Twist` (what `cmd_vel` carries on most robots).
    #[default]
    Twist,
    /// `geometry_msgs/msg/TwistStamped` (ros2_control's diff_drive_controller from Jazzy on).
    TwistStamped,
}

impl CommandType {
    /// The ROS 2 type name, as MCAP schema names it.
    pub fn schema_name(self) -> &'static str {
        match self {
            CommandType::Twist => "geometry_msgs/msg/Twist",
            CommandType::TwistStamped => "geometry_msgs/msg/TwistStamped",
        }
    }

    fn from_schema_name(name: &str) -> Option<Self> {
        [CommandType::Twist, CommandType::TwistStamped]
            .into_iter()
            .find(|c| c.schema_name() == name)
    }

    fn definition(self) -> String {
        match self {
            CommandType::Twist => ros::twist_definition(),
            CommandType::TwistStamped => ros::twist_stamped_definition(),
        }
    }
}

/// The topics of a bag: where the commands and the odometry are.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BagTopics {
    /// The command topic (default `/cmd_vel`).
    pub command: String,
    /// The odometry topic, `nav_msgs/msg/Odometry` (default `/odom`).
    pub odometry: String,
    /// The command type to write (default `twist`). Reading detects it from the schema instead.
    pub command_type: CommandType,
}

impl Default for BagTopics {
    fn default() -> Self {
        Self {
            command: "/cmd_vel".into(),
            odometry: "/odom".into(),
            command_type: CommandType::Twist,
        }
    }
}

/// One decoded message: its time \[ns\] and its content.
struct Stamped<T> {
    ns: i64,
    msg: T,
}

/// Reads the drive in the ROS 2 bag at `path` (one MCAP file) into a [`Recording`].
///
/// The odometry messages (`nav_msgs/msg/Odometry` on `topics.odometry`) set the sample
/// instants: t is the time (per `time_source`) since the first of them \[s\], v =
/// `twist.twist.linear.x` [m/s], ω = `twist.twist.angular.z` [rad/s], x, y =
/// `pose.pose.position` \[m\], φ the quaternion's yaw \[rad\], unwrapped. The command at each
/// instant is the last message on `topics.command` at or before it (zero-order hold; zero
/// before the first), `geometry_msgs/msg/Twist` or `TwistStamped` as the channel's schema says:
/// v_ref = `linear.x`, ω_ref = `angular.z`. With `command_timeout_s`, a command older than that
/// counts as zero, as a ROS base controller stops on a stale `cmd_vel` (diff_drive_controller's
/// `cmd_vel_timeout`, 0.5 s by default). Messages may come in any order in the file; equal
/// times keep file order, so of two commands at one instant the later in the file holds.
///
/// The metadata name the bag, topics, command type, time source and the absolute time of
/// t = 0 (`t0_ns`), with `command_hold: zoh`. How the rows were stamped (`timing`,
/// `velocity_sampling`) comes from the bag's `wheelid` metadata record when [`write_mcap`]
/// wrote it; a bag from elsewhere says nothing of it (an Odometry twist may be an instant or a
/// mean over the odometry's last cycle), so nothing is claimed and identification estimates
/// it.
///
/// # Errors
/// All name the file. [`RobotError::Io`] if it cannot be opened or read;
/// [`RobotError::Protocol`] if it is not valid MCAP (bad magic, a CRC that does not match, a
/// truncated file, a record over 512 MiB) or a message does not
/// decode (with its topic, index on the topic and log time), or the samples are not valid (two
/// odometry messages at one time, a non-finite value); [`RobotError::Setting`] if a topic is
/// missing (listing the topics present), carries another type (naming it) or another encoding
/// than `cdr`, if `time_source` is `header_stamp` with `Twist` commands (no stamp), or if
/// `command_timeout_s` is not positive.
pub fn read_mcap(
    path: &Path,
    topics: &BagTopics,
    time_source: TimeSource,
    command_timeout_s: Option<f64>,
) -> Result<Recording, RobotError> {
    let timeout_ns = match command_timeout_s {
        None => None,
        Some(s) if s.is_finite() && s > 0.0 => Some((s * 1e9).round() as i64),
        Some(s) => {
            return Err(RobotError::Setting(format!(
                "command_timeout_s = {s} must be positive"
            )));
        }
    };
    let file_name = path.display().to_string();
    check_attachments(path)
        .map_err(|e| RobotError::Protocol(format!("{file_name}: not a valid MCAP file: {e}")))?;
    // The mcap crate can still panic on a malformed record the check above does not know of:
    // a bag that makes it panic is a bad bag, not a crash.
    let (bag, metadata) = std::panic::catch_unwind(|| {
        (
            Messages::read(path, topics, time_source),
            wheelid_metadata(path),
        )
    })
    .map_err(|_| {
        RobotError::Protocol(format!(
            "{file_name}: not a valid MCAP file (the MCAP reader failed on a malformed record)"
        ))
    })?;
    let mut rec = bag?.align(path, topics, timeout_ns)?;
    // What the writer said of its stamping (a wheelid bag); a bag from a robot says nothing, and
    // nothing is claimed for it: identification estimates the convention.
    for (key, value) in metadata {
        rec.set_meta(&key, value);
    }
    for (key, value) in [
        ("command_topic", topics.command.clone()),
        ("odometry_topic", topics.odometry.clone()),
        ("time_source", time_source.as_str().to_owned()),
    ] {
        rec.set_meta(key, value);
    }
    if let Some(s) = command_timeout_s {
        rec.set_meta("command_timeout_s", s.to_string());
    }
    Ok(rec)
}

/// Checks the top-level attachment records of the MCAP file at `path`, which mcap 0.26 slices
/// without checking (an attachment whose body is shorter than its own header says panics it;
/// found by fuzzing, `fuzz/`): each one's body must hold its header, data and CRC. Other
/// records are skipped over; anything else malformed is left for the reader to report.
///
/// Record layout (MCAP specification): opcode u8, length u64 LE, body; an attachment body is
/// log_time u64, create_time u64, name (u32 length + bytes), media_type (likewise), data_len
/// u64, data, crc u32.
fn check_attachments(path: &Path) -> Result<(), String> {
    use std::io::Read;
    const MAGIC: usize = 8;
    const ATTACHMENT: u8 = 0x09;
    const CHUNK: u8 = 0x06;
    const FOOTER: u8 = 0x02;
    let Ok(file) = File::open(path) else {
        return Ok(()); // the reader reports it, naming the file
    };
    let mut input = BufReader::new(file);
    let mut head = [0u8; 9];
    if input.read_exact(&mut head[..MAGIC]).is_err() {
        return Ok(());
    }
    while input.read_exact(&mut head).is_ok() {
        let len = u64::from_le_bytes(head[1..9].try_into().unwrap_or_default());
        if head[0] == FOOTER || len > RECORD_LENGTH_LIMIT as u64 {
            return Ok(());
        }
        if head[0] != ATTACHMENT && head[0] != CHUNK {
            if input.seek_relative(len as i64).is_err() {
                return Ok(());
            }
            continue;
        }
        let mut body = vec![0u8; len as usize];
        if input.read_exact(&mut body).is_err() {
            return Ok(());
        }
        if head[0] == ATTACHMENT {
            attachment_fits(&body).ok_or("an attachment record is shorter than its header says")?;
        } else {
            chunk_records_fit(&body).ok_or("a chunk's record runs past the chunk")?;
        }
    }
    Ok(())
}

/// Whether every record of an uncompressed chunk's body ends inside the chunk's records (mcap
/// 0.26's reader subtracts their lengths from what remains unchecked). A compressed chunk, or
/// a body too short to tell, passes: the reader reports those itself.
fn chunk_records_fit(body: &[u8]) -> Option<()> {
    let (u32_at, u64_at) = (|at| u32_at(body, at), |at| u64_at(body, at));
    let Some(compression_len) = u32_at(28) else {
        return Some(());
    };
    let records_at = 32usize.checked_add(compression_len)?;
    if compression_len != 0 {
        return Some(());
    }
    let Some(records_len) = u64_at(records_at) else {
        return Some(());
    };
    let mut left = records_len;
    let mut at = records_at + 8;
    while left > 0 {
        // opcode (1) + length (8) + the record.
        let len = u64_at(at + 1)?;
        let whole = len.checked_add(9)?;
        left = left.checked_sub(whole)?;
        at = at.checked_add(usize::try_from(whole).ok()?)?;
    }
    Some(())
}

/// The little-endian u32 at byte `at` of `body`, as a length; `None` past its end.
fn u32_at(body: &[u8], at: usize) -> Option<usize> {
    let bytes = body.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(bytes.try_into().ok()?) as usize)
}

/// The little-endian u64 at byte `at` of `body`; `None` past its end.
fn u64_at(body: &[u8], at: usize) -> Option<u64> {
    let bytes = body.get(at..at.checked_add(8)?)?;
    Some(u64::from_le_bytes(bytes.try_into().ok()?))
}

/// Whether an attachment record's body holds its header, its data and the CRC.
fn attachment_fits(body: &[u8]) -> Option<()> {
    let name_end = 16usize.checked_add(4)?.checked_add(u32_at(body, 16)?)?;
    let media_end = name_end
        .checked_add(4)?
        .checked_add(u32_at(body, name_end)?)?;
    let data_len = u64_at(body, media_end)?;
    let end = (media_end as u64)
        .checked_add(8)?
        .checked_add(data_len)?
        .checked_add(4)?;
    (end <= body.len() as u64).then_some(())
}

/// The messages of the two topics, decoded and timed, in time order.
struct Messages {
    odometry: Vec<Stamped<Odometry>>,
    commands: Vec<Stamped<Twist>>,
    command_type: CommandType,
}

/// No message on `topic` of the bag `file_name`, whose topics `present` (with their schemas)
/// the error lists.
fn missing_topic(file_name: &str, topic: &str, present: &BTreeMap<String, String>) -> RobotError {
    let list: Vec<String> = present.iter().map(|(t, s)| format!("{t} ({s})")).collect();
    let list = if list.is_empty() {
        "none".to_owned()
    } else {
        list.join(", ")
    };
    RobotError::Setting(format!(
        "{file_name}: no messages on topic `{topic}`; topics present: {list}"
    ))
}

/// The odometry messages of `topic`, in time order, each at its own time.
///
/// # Errors
/// [`RobotError::Protocol`] naming the first two samples with the same time.
fn distinct_times(
    file_name: &str,
    topic: &str,
    time_source: TimeSource,
    odometry: &[Stamped<Odometry>],
) -> Result<(), RobotError> {
    let Some(k) = odometry.windows(2).position(|p| p[1].ns == p[0].ns) else {
        return Ok(());
    };
    let hint = match time_source {
        TimeSource::HeaderStamp => " (are the header stamps set?)",
        TimeSource::LogTime => "",
    };
    Err(RobotError::Protocol(format!(
        "{file_name}: topic `{topic}`: samples {k} and {} (in time order) have the same time \
         {} s{hint}",
        k + 1,
        odometry[k].ns as f64 * 1e-9,
    )))
}

impl Messages {
    /// Reads and decodes the odometry and command messages of the bag at `path`.
    fn read(path: &Path, topics: &BagTopics, time_source: TimeSource) -> Result<Self, RobotError> {
        let file_name = path.display().to_string();
        let file =
            File::open(path).map_err(|e| RobotError::io(format!("{file_name}: opening"), e))?;
        let options = LinearReaderOptions::default()
            .with_prevalidate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(RECORD_LENGTH_LIMIT);
        let mut present: BTreeMap<String, String> = BTreeMap::new();
        let mut odometry: Vec<Stamped<Odometry>> = Vec::new();
        let mut commands: Vec<Stamped<Twist>> = Vec::new();
        let mut command_type = None;
        for message in MessageReader::new_with_options(BufReader::new(file), options) {
            let m = message.map_err(|e| mcap_error(&file_name, e))?;
            let topic = m.channel.topic.as_str();
            let schema = m.channel.schema.as_ref().map_or("", |s| s.name.as_str());
            present
                .entry(topic.to_owned())
                .or_insert_with(|| schema.to_owned());
            let is_odometry = topic == topics.odometry;
            if !is_odometry && topic != topics.command {
                continue;
            }
            if m.channel.message_encoding != "cdr" {
                return Err(RobotError::Setting(format!(
                    "{file_name}: topic `{topic}` has message encoding `{}`, not `cdr` (ROS 2)",
                    m.channel.message_encoding
                )));
            }
            let index = if is_odometry {
                odometry.len()
            } else {
                commands.len()
            };
            let at = || {
                format!(
                    "{file_name}: topic `{topic}`, message index {index} (log time {} s)",
                    seconds(m.log_time)
                )
            };
            let log_ns = i64::try_from(m.log_time)
                .map_err(|_| RobotError::Protocol(format!("{}: log time out of range", at())))?;
            let decode_error = |e: ros::CdrError| {
                RobotError::Protocol(format!("{}: cannot decode `{schema}`: {e}", at()))
            };
            let stamp_ns = |h: &Header| match time_source {
                TimeSource::LogTime => log_ns,
                TimeSource::HeaderStamp => h.stamp.nanos(),
            };
            if is_odometry {
                if schema != ODOMETRY {
                    return Err(wrong_schema(&file_name, topic, schema, ODOMETRY));
                }
                let msg: Odometry = ros::from_cdr(&m.data).map_err(decode_error)?;
                let ns = stamp_ns(&msg.header);
                odometry.push(Stamped { ns, msg });
                continue;
            }
            let Some(kind) = CommandType::from_schema_name(schema) else {
                let expected = "geometry_msgs/msg/Twist or geometry_msgs/msg/TwistStamped";
                return Err(wrong_schema(&file_name, topic, schema, expected));
            };
            command_type = Some(kind);
            commands.push(match kind {
                CommandType::Twist if time_source == TimeSource::HeaderStamp => {
                    return Err(RobotError::Setting(format!(
                        "{file_name}: time_source = \"header_stamp\" needs stamped commands, but \
                         `{topic}` carries geometry_msgs/msg/Twist (no header); use \"log_time\""
                    )));
                }
                CommandType::Twist => Stamped {
                    ns: log_ns,
                    msg: ros::from_cdr::<Twist>(&m.data).map_err(decode_error)?,
                },
                CommandType::TwistStamped => {
                    let msg: TwistStamped = ros::from_cdr(&m.data).map_err(decode_error)?;
                    let ns = stamp_ns(&msg.header);
                    Stamped { ns, msg: msg.twist }
                }
            });
        }
        if odometry.is_empty() {
            return Err(missing_topic(&file_name, &topics.odometry, &present));
        }
        let Some(command_type) = command_type else {
            return Err(missing_topic(&file_name, &topics.command, &present));
        };
        // Stable sorts: equal times keep file order.
        odometry.sort_by_key(|s| s.ns);
        commands.sort_by_key(|s| s.ns);
        distinct_times(&file_name, &topics.odometry, time_source, &odometry)?;
        Ok(Self {
            odometry,
            commands,
            command_type,
        })
    }

    /// The recording: a row per odometry message, with the command held at its time.
    fn align(
        &self,
        path: &Path,
        topics: &BagTopics,
        timeout_ns: Option<i64>,
    ) -> Result<Recording, RobotError> {
        let (odometry, commands) = (&self.odometry, &self.commands);
        let Some(first) = odometry.first() else {
            return Err(RobotError::Setting(format!(
                "{}: no odometry on `{}`",
                path.display(),
                topics.odometry
            )));
        };
        let n = odometry.len();
        let mut cols: [Vec<f64>; 8] = std::array::from_fn(|_| Vec::with_capacity(n));
        let mut next_command = 0;
        let mut heading = 0.0;
        for (k, o) in odometry.iter().enumerate() {
            while next_command < commands.len() && commands[next_command].ns <= o.ns {
                next_command += 1;
            }
            let held = next_command
                .checked_sub(1)
                .map(|j| &commands[j])
                .filter(|c| timeout_ns.is_none_or(|limit| o.ns - c.ns <= limit))
                .map_or((0.0, 0.0), |c| (c.msg.linear.x, c.msg.angular.z));
            let p = &o.msg.pose.pose;
            let yaw = p.orientation.yaw();
            heading = if k == 0 {
                yaw
            } else {
                heading + wrap_to_pi(yaw - heading)
            };
            let twist = &o.msg.twist.twist;
            let row = [
                (o.ns - first.ns) as f64 / 1e9,
                held.0,
                held.1,
                twist.linear.x,
                twist.angular.z,
                p.position.x,
                p.position.y,
                heading,
            ];
            for (col, value) in cols.iter_mut().zip(row) {
                col.push(value);
            }
        }
        let [t, v_ref, w_ref, v, w, x, y, phi] = cols;
        let mut rec = Recording::new(path, t, v_ref, w_ref, v, w).map_err(core_error)?;
        rec.x = Some(x);
        rec.y = Some(y);
        rec.phi = Some(phi);
        check_recording(&rec)?;
        let frames = format!(
            "{} / {}",
            first.msg.header.frame_id, first.msg.child_frame_id
        );
        for (key, value) in [
            ("source", format!("ROS 2 bag {}", path.display())),
            ("command_type", self.command_type.schema_name().to_owned()),
            ("odometry_frames", frames),
            ("t0_ns", first.ns.to_string()),
            ("command_hold", "zoh".to_owned()),
        ] {
            rec.set_meta(key, value);
        }
        Ok(rec)
    }
}

/// Writes `rec` as a ROS 2 bag: one MCAP file at `path` that rosbag2 (`ros2 bag play
/// file.mcap`), Foxglove and [`read_mcap`] read.
///
/// Profile `ros2`; two schemas (`nav_msgs/msg/Odometry` and the command type of `topics`,
/// encoding `ros2msg`, data the `.msg` text with dependencies); two channels (message
/// encoding `cdr`, metadata `offered_qos_profiles: []`, i.e. the default QoS); zstd-compressed
/// chunks. At each sample time t_k it writes the command (v_ref, ω_ref) as `linear.x`,
/// `angular.z` and the odometry: header stamp t_k in frame `odom`, child frame `base_link`
/// (REP 105), position (x, y, 0), orientation the yaw φ about z, twist (v, 0, 0; 0, 0, ω), zero
/// covariances; pose zero if the recording has none. Log, publish and header times are
/// t_k − t_0 in whole ns since the epoch, so the bag's clock starts at 0 and [`read_mcap`]
/// gives back t − t_0.
///
/// The file is written to a temporary file in the same directory and renamed at the end, so
/// a failure leaves no partial bag. A metadata record `wheelid` keeps the recording's
/// `timing`, `velocity_sampling`, `robot`, `theta_true`, `theta_map`, `effects` and `jitter`.
///
/// # Errors
/// [`RobotError::Protocol`] if `rec` is invalid (ragged or non-finite columns, time not
/// increasing, a time past 2038 after t_0); [`RobotError::Io`] naming `path` if it cannot be
/// written.
pub fn write_mcap(rec: &Recording, path: &Path, topics: &BagTopics) -> Result<(), RobotError> {
    check_recording(rec)?;
    let bytes = encode_bag(rec, topics)
        .map_err(|e| RobotError::Protocol(format!("{}: encoding the bag: {e}", path.display())))?;
    wheelid_core::recording::write_atomic(path, &bytes).map_err(core_error)
}

/// What can fail while encoding a bag in memory.
#[derive(Debug, thiserror::Error)]
enum EncodeError {
    #[error(transparent)]
    Mcap(#[from] ::mcap::McapError),
    #[error(transparent)]
    Cdr(#[from] ros::CdrError),
    #[error("time {0} s after the start is past what a ROS 2 time holds")]
    Time(f64),
}

/// Name of the MCAP metadata record in which wheelid keeps a recording's metadata.
pub const METADATA_NAME: &str = "wheelid";

/// Recording metadata kept in a bag (the rest is rebuilt from the messages).
const KEPT: [&str; 7] = [
    "timing",
    "velocity_sampling",
    "robot",
    "theta_true",
    "theta_map",
    "effects",
    "jitter",
];

/// The `wheelid` metadata record of the bag at `path`, if it has one (any read error: none).
fn wheelid_metadata(path: &Path) -> Vec<(String, String)> {
    let Ok(bytes) = std::fs::read(path) else {
        return Vec::new();
    };
    let Ok(reader) = ::mcap::read::LinearReader::new(&bytes) else {
        return Vec::new();
    };
    // The reader repeats its error on a damaged bag rather than ending: stop at the first.
    for record in reader.map_while(Result::ok) {
        if let ::mcap::records::Record::Metadata(m) = record
            && m.name == METADATA_NAME
        {
            return m
                .metadata
                .into_iter()
                .filter(|(k, _)| KEPT.contains(&k.as_str()))
                .collect();
        }
    }
    Vec::new()
}

fn encode_bag(rec: &Recording, topics: &BagTopics) -> Result<Vec<u8>, EncodeError> {
    let mut w = ::mcap::WriteOptions::new()
        .profile("ros2")
        .create(Cursor::new(Vec::new()))?;
    let qos = BTreeMap::from([("offered_qos_profiles".to_owned(), "[]".to_owned())]);
    let kind = topics.command_type;
    let odom_schema = w.add_schema(ODOMETRY, "ros2msg", ros::odometry_definition().as_bytes())?;
    let cmd_schema = w.add_schema(kind.schema_name(), "ros2msg", kind.definition().as_bytes())?;
    let odom_channel = w.add_channel(odom_schema, &topics.odometry, "cdr", &qos)?;
    let cmd_channel = w.add_channel(cmd_schema, &topics.command, "cdr", &qos)?;
    let kept: BTreeMap<String, String> = KEPT
        .iter()
        .filter_map(|k| rec.meta(k).map(|v| ((*k).to_owned(), v.to_owned())))
        .collect();
    w.write_metadata(&::mcap::records::Metadata {
        name: METADATA_NAME.to_owned(),
        metadata: kept,
    })?;
    let t0 = rec.t.first().copied().unwrap_or(0.0);
    let column = |c: &Option<Vec<f64>>, k: usize| c.as_ref().map_or(0.0, |c| c[k]);
    for k in 0..rec.len() {
        let dt = rec.t[k] - t0;
        let ns = (dt * 1e9).round() as i64;
        let stamp = Time::from_nanos(ns).ok_or(EncodeError::Time(dt))?;
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.to_owned(),
        };
        let twist = Twist::planar(rec.v_ref[k], rec.w_ref[k]);
        let command = match kind {
            CommandType::Twist => ros::to_cdr(&twist)?,
            CommandType::TwistStamped => ros::to_cdr(&TwistStamped {
                header: header(BASE_FRAME),
                twist,
            })?,
        };
        let odometry = Odometry {
            header: header(ODOM_FRAME),
            child_frame_id: BASE_FRAME.to_owned(),
            pose: ros::PoseWithCovariance {
                pose: ros::Pose {
                    position: ros::Point {
                        x: column(&rec.x, k),
                        y: column(&rec.y, k),
                        z: 0.0,
                    },
                    orientation: ros::Quaternion::from_yaw(column(&rec.phi, k)),
                },
                covariance: [0.0; 36],
            },
            twist: ros::TwistWithCovariance {
                twist: Twist::planar(rec.v[k], rec.w[k]),
                covariance: [0.0; 36],
            },
        };
        let sequence = u32::try_from(k).unwrap_or(u32::MAX);
        for (channel_id, data) in [
            (cmd_channel, command),
            (odom_channel, ros::to_cdr(&odometry)?),
        ] {
            let header = ::mcap::records::MessageHeader {
                channel_id,
                sequence,
                log_time: ns as u64,
                publish_time: ns as u64,
            };
            w.write_to_known_channel(&header, &data)?;
        }
    }
    w.finish()?;
    Ok(w.into_inner().into_inner())
}

fn mcap_error(file: &str, e: ::mcap::McapError) -> RobotError {
    match e {
        ::mcap::McapError::Io(source) => RobotError::io(format!("{file}: reading"), source),
        e => RobotError::Protocol(format!("{file}: not a valid MCAP file: {e}")),
    }
}

fn wrong_schema(file: &str, topic: &str, found: &str, expected: &str) -> RobotError {
    let found = if found.is_empty() { "no schema" } else { found };
    RobotError::Setting(format!(
        "{file}: topic `{topic}` carries `{found}`, expected {expected}"
    ))
}

/// `ns` nanoseconds as seconds with all nine decimals.
fn seconds(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// `a` wrapped to (−π, π].
fn wrap_to_pi(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let r = a.rem_euclid(TAU);
    if r > PI { r - TAU } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_to_the_half_open_interval() {
        use std::f64::consts::PI;
        assert_eq!(wrap_to_pi(0.0), 0.0);
        assert_eq!(wrap_to_pi(PI), PI);
        assert!((wrap_to_pi(-PI) - PI).abs() < 1e-15);
        assert!((wrap_to_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((wrap_to_pi(-6.2) - (2.0 * PI - 6.2)).abs() < 1e-15);
    }

    #[test]
    fn log_times_print_with_nine_decimals() {
        assert_eq!(seconds(1_700_000_000_000_000_042), "1700000000.000000042");
        assert_eq!(seconds(5), "0.000000005");
    }
}
