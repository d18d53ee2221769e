//! wheelid
