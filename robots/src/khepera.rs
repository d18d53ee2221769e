//! Khepera III backend over the serial text protocol (to be written).
