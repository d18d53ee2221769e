//! Replay backend: a recording (CSV or ROS 2 MCAP bag) as a robot (to be written).
