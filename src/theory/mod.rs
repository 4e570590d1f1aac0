//! Kinetic theory of polydisperse granular gases (paper section II): pure functions, usable
//! without simulating.

pub mod temperature;
