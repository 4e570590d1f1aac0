//! Numerics with no physics in them, shared by the theory, the simulators and the analysis:
//! [`quad`] (Gauss-Legendre rules, adaptive and composite quadrature, Gamma), [`ode`] (a stiff
//! Radau IIA integrator), [`fit`] (weighted least squares, power laws, Levenberg-Marquardt,
//! the stretched-exponential fits), [`power`] (power laws over a window of x: decay and growth
//! exponents), [`stats`] (mean and standard error).

pub mod fit;
pub mod ode;
pub mod power;
pub mod quad;
pub mod stats;
