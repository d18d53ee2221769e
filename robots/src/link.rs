//! The byte link to a real robot, shared by the serial/TCP backends ([`crate::pioneer`],
//! [`crate::khepera`]): `tcp://host:port` is a TCP connection (to a simulator such as
//! MobileSim, or a TCP–serial bridge), anything else a serial device path.

use std::io;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

use wheelid_core::RobotError;

/// An open link: a socket or a serial port.
pub enum Port {
    /// A TCP connection: connect, read and write timeouts set, Nagle off (one small packet per
    /// command and per report: never wait to coalesce them).
    Tcp(TcpStream),
    /// A serial device (8N1, read timeout set).
    Serial(Box<dyn serialport::SerialPort>),
}

/// Opens `port` (`tcp://host:port`, else a serial device at `baud`) with `timeout` for
/// connecting and for each read and write.
///
/// # Errors
/// [`RobotError::Io`] naming the port and the step that failed: `resolving the address`,
/// `connecting`, `configuring the socket`, or `opening the serial port at <baud> baud`.
pub fn open(port: &str, baud: u32, timeout: Duration) -> Result<Port, RobotError> {
    let port = port.trim();
    let Some(address) = port.strip_prefix("tcp://") else {
        let serial = serialport::new(port, baud)
            .timeout(timeout)
            .open()
            .map_err(|e| {
                RobotError::io(
                    format!("{port}: opening the serial port at {baud} baud"),
                    e.into(),
                )
            })?;
        return Ok(Port::Serial(serial));
    };
    let what = |op: &str| format!("{port}: {op}");
    let addrs: Vec<_> = address
        .to_socket_addrs()
        .map_err(|e| RobotError::io(what("resolving the address"), e))?
        .collect();
    let mut last = io::Error::new(io::ErrorKind::NotFound, "the address resolves to nothing");
    for addr in addrs {
        match TcpStream::connect_timeout(&addr, timeout) {
            Ok(stream) => {
                stream
                    .set_read_timeout(Some(timeout))
                    .and_then(|()| stream.set_write_timeout(Some(timeout)))
                    .and_then(|()| stream.set_nodelay(true))
                    .map_err(|e| RobotError::io(what("configuring the socket"), e))?;
                return Ok(Port::Tcp(stream));
            }
            Err(e) => last = e,
        }
    }
    Err(RobotError::io(what("connecting"), last))
}

/// Whether a read error only means "nothing yet" (a timeout or an interrupted call) rather than
/// a broken link.
pub fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}
