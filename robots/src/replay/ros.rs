//! The ROS 2 messages a replay reads and writes, as serde mirrors of their `.msg` definitions,
//! and their CDR encoding.
//!
//! Each struct lists the fields of its `.msg` file in order, with the same primitive types
//! (`float64` → `f64`, `int32` → `i32`, `uint32` → `u32`, `string` → `String`,
//! `float64[36]` → `[f64; 36]`), so that serde visits them in the order CDR lays them out.
//! Sources: `builtin_interfaces/msg/Time`, `std_msgs/msg/Header`, `geometry_msgs/msg/{Vector3,
//! Point, Quaternion, Pose, PoseWithCovariance, Twist, TwistWithCovariance, TwistStamped}` and
//! `nav_msgs/msg/Odometry` (ROS 2 Humble and later; unchanged since Foxy).
//!
//! **CDR** (the `cdr` message encoding of the MCAP registry, as rosbag2 stores it): a 4-byte
//! encapsulation header — representation identifier `00 01` (CDR little endian) or `00 00`
//! (CDR big endian), then 2 option bytes — followed by the XCDR1 stream: each primitive aligned
//! to its own size counted from the end of the header, a string as a `u32` length that counts the
//! terminating NUL, the bytes, then the NUL; fixed arrays as their elements, without a length.
//!
//! Conventions (REP 103, REP 105): x forward, y left, z up; yaw counter-clockwise about z; the
//! odometry pose is in `header.frame_id` (usually `odom`), its twist in `child_frame_id`
//! (usually `base_link`).

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

/// The encapsulation header of a CDR little-endian payload (`CDR_LE`, no options).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// `builtin_interfaces/msg/Time`: `int32 sec`, `uint32 nanosec`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds \[s\].
    pub sec: i32,
    /// Nanoseconds \[ns\], 0 ≤ nanosec < 10⁹.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch, or `None` if the seconds overflow `i32`.
    pub fn from_nanos(ns: i64) -> Option<Self> {
        let sec = i32::try_from(ns.div_euclid(1_000_000_000)).ok()?;
        let nanosec = u32::try_from(ns.rem_euclid(1_000_000_000)).ok()?;
        Some(Self { sec, nanosec })
    }

    /// Nanoseconds since the epoch.
    pub fn nanos(&self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// `std_msgs/msg/Header`: `builtin_interfaces/Time stamp`, `string frame_id`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When the data were taken.
    pub stamp: Time,
    /// The coordinate frame of the data.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3`: `float64 x, y, z`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Point`: `float64 x, y, z` \[m\].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
    /// z \[m\].
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`: `float64 x, y, z, w` (Hamilton, w the scalar part).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w (scalar part).
    pub w: f64,
}

impl Quaternion {
    /// The rotation by `yaw` \[rad\] about z: (0, 0, sin(yaw/2), cos(yaw/2)).
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (0.5 * yaw).sin_cos();
        Self {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// The yaw \[rad\] in (−π, π]: the z-y-x Euler angle ψ = atan2(2(wz + xy), 1 − 2(y² + z²)).
    ///
    /// Written as atan2(2(wz + xy), w² + x² − y² − z²), equal for a unit quaternion and
    /// unchanged by scaling, so a slightly unnormalised quaternion gives the same yaw.
    pub fn yaw(&self) -> f64 {
        let Self { x, y, z, w } = *self;
        (2.0 * (w * z + x * y)).atan2(w * w + x * x - y * y - z * z)
    }
}

/// `geometry_msgs/msg/Pose`: `Point position`, `Quaternion orientation`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position \[m\].
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`: `Pose pose`, `float64[36] covariance` (row-major
/// 6×6 over x, y, z, roll, pitch, yaw).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6 covariance.
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/msg/Twist`: `Vector3 linear` [m/s], `Vector3 angular` [rad/s].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity [m/s]; x is forward for a base.
    pub linear: Vector3,
    /// Angular velocity [rad/s]; z is the yaw rate.
    pub angular: Vector3,
}

impl Twist {
    /// The planar twist of a differential drive: linear.x = `v` [m/s], angular.z = `w` [rad/s].
    pub fn planar(v: f64, w: f64) -> Self {
        Self {
            linear: Vector3 {
                x: v,
                ..Vector3::default()
            },
            angular: Vector3 {
                z: w,
                ..Vector3::default()
            },
        }
    }
}

/// `geometry_msgs/msg/TwistWithCovariance`: `Twist twist`, `float64[36] covariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6×6 covariance.
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/msg/TwistStamped`: `std_msgs/Header header`, `Twist twist`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The twist.
    pub twist: Twist,
}

/// `nav_msgs/msg/Odometry`: `std_msgs/Header header`, `string child_frame_id`,
/// `PoseWithCovariance pose` (in `header.frame_id`), `TwistWithCovariance twist` (in
/// `child_frame_id`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the pose's frame (usually `odom`).
    pub header: Header,
    /// The twist's frame (usually `base_link`).
    pub child_frame_id: String,
    /// Pose of `child_frame_id` in `header.frame_id`.
    pub pose: PoseWithCovariance,
    /// Velocity of `child_frame_id`, expressed in `child_frame_id`.
    pub twist: TwistWithCovariance,
}

/// Why a CDR payload could not be decoded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// Shorter than the 4-byte encapsulation header.
    #[error("{0} bytes, shorter than the 4-byte CDR encapsulation header")]
    TooShort(usize),
    /// An encapsulation other than plain CDR (XCDR1) little or big endian.
    #[error(
        "encapsulation `{0:02x} {1:02x}` is not plain CDR (`00 01` little or `00 00` big endian)"
    )]
    Encapsulation(u8, u8),
    /// The stream does not match the message layout (too short, bad string, …).
    #[error("{0}")]
    Decode(#[from] cdr_encoding::Error),
}

/// Encodes `msg` as a CDR little-endian payload: [`CDR_LE_HEADER`], then the XCDR1 stream.
///
/// # Errors
/// [`CdrError::Decode`] if serde reports an error (not for the message types here).
pub fn to_cdr<T: Serialize>(msg: &T) -> Result<Vec<u8>, CdrError> {
    let body = cdr_encoding::to_vec::<T, byteorder::LittleEndian>(msg)?;
    Ok([CDR_LE_HEADER.as_slice(), &body].concat())
}

/// Decodes a CDR payload (little or big endian, per its encapsulation header). Bytes after the
/// message (the alignment padding a DDS writer may add) are ignored.
///
/// # Errors
/// [`CdrError`] for a short payload, another encapsulation or a stream that does not fit `T`.
pub fn from_cdr<T: DeserializeOwned>(data: &[u8]) -> Result<T, CdrError> {
    let (Some(head), Some(body)) = (data.get(..4), data.get(4..)) else {
        return Err(CdrError::TooShort(data.len()));
    };
    let msg = match (head[0], head[1]) {
        (0x00, 0x01) => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body)?.0,
        (0x00, 0x00) => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body)?.0,
        (a, b) => return Err(CdrError::Encapsulation(a, b)),
    };
    Ok(msg)
}

/// The line that separates a dependency in a `ros2msg` schema: 80 `=`.
const SEPARATOR: &str =
    "================================================================================";

const TIME_MSG: &str = "int32 sec\nuint32 nanosec\n";
const HEADER_MSG: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3_MSG: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const POINT_MSG: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION_MSG: &str = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";
const POSE_MSG: &str = "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";
const POSE_COV_MSG: &str = "geometry_msgs/Pose pose\nfloat64[36] covariance\n";
const TWIST_MSG: &str = "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n";
const TWIST_COV_MSG: &str = "geometry_msgs/Twist twist\nfloat64[36] covariance\n";
const TWIST_STAMPED_MSG: &str = "std_msgs/Header header\ngeometry_msgs/Twist twist\n";
const ODOMETRY_MSG: &str = "std_msgs/Header header\nstring child_frame_id\n\
     geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n";

/// Joins a top-level definition and its dependencies in the `ros2msg` schema format of the
/// MCAP registry: the top-level `.msg` text first, then for each dependency a line of 80 `=`,
/// a line `MSG: <package>/<Name>`, and its `.msg` text. Type names are written in full and
/// comments and default values left out, as the Python `rosbags` writer does.
fn definition(top: &str, deps: &[(&str, &str)]) -> String {
    let mut out = top.to_owned();
    for (name, text) in deps {
        out.push_str(&format!("{SEPARATOR}\nMSG: {name}\n{text}"));
    }
    out
}

/// The `ros2msg` schema text of `geometry_msgs/msg/Twist` (comments left out).
pub fn twist_definition() -> String {
    definition(TWIST_MSG, &[("geometry_msgs/Vector3", VECTOR3_MSG)])
}

/// The `ros2msg` schema text of `geometry_msgs/msg/TwistStamped` (comments left out).
pub fn twist_stamped_definition() -> String {
    definition(
        TWIST_STAMPED_MSG,
        &[
            ("std_msgs/Header", HEADER_MSG),
            ("builtin_interfaces/Time", TIME_MSG),
            ("geometry_msgs/Twist", TWIST_MSG),
            ("geometry_msgs/Vector3", VECTOR3_MSG),
        ],
    )
}

/// The `ros2msg` schema text of `nav_msgs/msg/Odometry` (comments left out).
pub fn odometry_definition() -> String {
    definition(
        ODOMETRY_MSG,
        &[
            ("std_msgs/Header", HEADER_MSG),
            ("builtin_interfaces/Time", TIME_MSG),
            ("geometry_msgs/PoseWithCovariance", POSE_COV_MSG),
            ("geometry_msgs/Pose", POSE_MSG),
            ("geometry_msgs/Point", POINT_MSG),
            ("geometry_msgs/Quaternion", QUATERNION_MSG),
            ("geometry_msgs/TwistWithCovariance", TWIST_COV_MSG),
            ("geometry_msgs/Twist", TWIST_MSG),
            ("geometry_msgs/Vector3", VECTOR3_MSG),
        ],
    )
}
