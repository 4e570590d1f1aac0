//! A species as the kinetic theory sees it: mass, diameter, number density.

/// One species as the theory sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Species {
    pub mass: f64,
    pub diameter: f64,
    /// Number density n_k.
    pub density: f64,
}

impl Species {
    pub fn new(mass: f64, diameter: f64, density: f64) -> Self {
        Species {
            mass,
            diameter,
            density,
        }
    }
}
