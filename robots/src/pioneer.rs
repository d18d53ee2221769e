//! Pioneer 3-DX backend over ARCOS (to be written).
