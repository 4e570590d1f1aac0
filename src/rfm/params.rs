//! RFM parameters (spec `rfm.md` section 1.1) and the quantities derived from them.
//!
//! [`RfmConfig`] is a plain struct holding every model parameter of issue 4 with the thesis
//! defaults (`Default` is the thesis's 2D system: N = 2000, L = 0.2 m, eps_n = eps_t = 0.6).
//! Derived quantities: the reduced mass m_12 = M/2, gamma_n from (2.6), gamma_t from (2.12),
//! omega_0, the damped frequency, the undamped contact time t_c = pi sqrt(m_12/k_s), the box
//! length from a packing fraction (2.24) or a reduced length (3.4), and the default time step.
//! [`RfmConfig::validate`] returns every error at once, each naming its field.

use serde::{Deserialize, Serialize};

/// Largest 2D packing fraction of the `uniform` initial layout: random sequential addition
/// (at spacing d (1 + 1e-3), giving up after 10^4 N tries) jams at ~0.547, so beyond this no
/// run can start. Below it the layout is random too: from ~0.5 on a start may fail for some
/// seeds (measured: 1 of 16 runs of 20 discs at 0.52, 1 of 4 of 3000 discs at 0.54; none of
/// 8 of 3000 or 12000 discs at 0.535). The thesis starts its uniform layouts at 0.53.
pub const UNIFORM_MAX_PACKING: f64 = 0.546;

/// Most particles of a run (particle indices are 32-bit).
pub const MAX_PARTICLES: usize = u32::MAX as usize - 1;

/// Initial placement of the particles (spec 1.9).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum InitialLayout {
    /// 2D: random non-overlapping positions (random sequential addition).
    /// 1D: evenly spaced (spacing L/N), the thesis's start.
    #[default]
    Uniform,
    /// 2D: square bed of touching discs (spacing d (1 + 1e-3)) filled from y = 0.
    Square,
    /// 2D: hexagonal bed (spacing d (1 + 1e-3), row pitch sqrt(3)/2 of that, rows offset by
    /// half a spacing) filled from y = 0.
    Hexagonal,
}

/// Every parameter of a Random Force Model run. SI units.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RfmConfig {
    /// Dimension: 1 (rods on a ring) or 2 (discs in a periodic square).
    pub dim: u32,
    pub n_particles: usize,
    /// Box side L (m). Exactly one of `box_length` and `packing_fraction` (2D) or
    /// `reduced_length` (1D) is given.
    pub box_length: Option<f64>,
    /// 2D packing fraction phi = N pi r^2 / L^2 (2.24).
    pub packing_fraction: Option<f64>,
    /// 1D reduced length L' = L - N d (3.4).
    pub reduced_length: Option<f64>,
    /// Radius r (m); diameter d = 2r.
    pub radius: f64,
    /// Particle mass M (kg).
    pub mass: f64,
    /// Spring constant k_s (kg s^-2).
    pub spring_constant: f64,
    /// Noise strength D (N^2 s): <eta eta> = 2 D delta(t) per component.
    pub noise_strength: f64,
    /// Normal restitution eps_n in (0, 1].
    pub restitution_normal: f64,
    /// Tangential restitution eps_t in (0, 1] (2D); 1 = no tangential dissipation.
    pub restitution_tangential: f64,
    /// Optional sliding-friction coefficient mu: caps the tangential impulse of a contact at
    /// mu times its normal impulse (with eps_t = 1 it is pure Coulomb sliding friction).
    pub friction: Option<f64>,
    /// Time step (s); `None` = [`RfmConfig::default_dt`].
    pub dt: Option<f64>,
    /// Simulated time before sampling starts (s).
    pub warmup: f64,
    /// Simulated time sampled after the warm-up (s).
    pub duration: f64,
    /// Steps between samples.
    pub sample_every: u64,
    pub initial_layout: InitialLayout,
}

/// Thesis radius (m), T 2.2.
pub const THESIS_RADIUS: f64 = 1.5e-3;
/// Thesis mass (kg), T 2.2 (spec 6.3: 3.53e-5, not 3.53e5).
pub const THESIS_MASS: f64 = 3.53e-5;
/// Thesis spring constant (kg s^-2).
pub const THESIS_SPRING: f64 = 5.0e5;
/// Thesis noise strength D (N^2 s).
pub const THESIS_NOISE: f64 = 1.0e-8;

impl Default for RfmConfig {
    /// The thesis's 2D system (sec. 2.3.2): N = 2000, L = 0.2 m, eps_n = eps_t = 0.6,
    /// dt = 1e-6 s (spec 1.5 [REC]), 1 s warm-up, sampled every 1000 steps.
    fn default() -> Self {
        RfmConfig {
            dim: 2,
            n_particles: 2000,
            box_length: Some(0.2),
            packing_fraction: None,
            reduced_length: None,
            radius: THESIS_RADIUS,
            mass: THESIS_MASS,
            spring_constant: THESIS_SPRING,
            noise_strength: THESIS_NOISE,
            restitution_normal: 0.6,
            restitution_tangential: 0.6,
            friction: None,
            dt: None,
            warmup: 1.0,
            duration: 1.0,
            sample_every: 1000,
            initial_layout: InitialLayout::Uniform,
        }
    }
}

impl RfmConfig {
    /// The thesis's 1D set-up (ch. 3): N rods on a ring of reduced length L' = 1 m, 20 s
    /// warm-up, sampled every 1000 steps.
    pub fn thesis_1d(n_particles: usize, eps: f64) -> Self {
        RfmConfig {
            dim: 1,
            n_particles,
            box_length: None,
            reduced_length: Some(1.0),
            restitution_normal: eps,
            restitution_tangential: 1.0,
            warmup: 20.0,
            ..RfmConfig::default()
        }
    }

    pub fn diameter(&self) -> f64 {
        2.0 * self.radius
    }

    /// Reduced mass m_12 = M/2 of two identical particles.
    pub fn reduced_mass(&self) -> f64 {
        0.5 * self.mass
    }

    /// omega_0 = sqrt(k_s / m_12).
    pub fn omega0(&self) -> f64 {
        (self.spring_constant / self.reduced_mass()).sqrt()
    }

    /// gamma_n from (2.6): -2 ln(eps) sqrt(m_12 k_s) / sqrt(pi^2 + ln^2 eps).
    pub fn gamma_n(&self) -> f64 {
        let l = self.restitution_normal.ln();
        -2.0 * l * (self.reduced_mass() * self.spring_constant).sqrt()
            / (std::f64::consts::PI.powi(2) + l * l).sqrt()
    }

    /// gamma_t from (2.12): -(sqrt(k_s m_12)/pi) ln eps_t (0 when eps_t = 1).
    pub fn gamma_t(&self) -> f64 {
        -(self.spring_constant * self.reduced_mass()).sqrt() / std::f64::consts::PI
            * self.restitution_tangential.ln()
    }

    /// Damping rate beta = gamma_n / (2 m_12) of the normal overlap.
    pub fn beta(&self) -> f64 {
        self.gamma_n() / (2.0 * self.reduced_mass())
    }

    /// Damped frequency omega_d = sqrt(omega_0^2 - beta^2).
    pub fn omega_d(&self) -> f64 {
        let (w0, b) = (self.omega0(), self.beta());
        (w0 * w0 - b * b).sqrt()
    }

    /// Undamped contact time t_c = pi sqrt(m_12 / k_s) (spec 1.1).
    pub fn contact_time(&self) -> f64 {
        std::f64::consts::PI / self.omega0()
    }

    /// Duration of a binary contact of the damped oscillator, pi / omega_d.
    pub fn damped_contact_time(&self) -> f64 {
        std::f64::consts::PI / self.omega_d()
    }

    /// The tangential restitution this model actually produces for a binary contact: the
    /// tangential dashpot (2.9) acts for pi/omega_d, not the undamped pi/omega_0 used in its
    /// calibration (2.11), so eps_t,eff = eps_t^(omega_0/omega_d) (spec 6.7).
    pub fn effective_tangential_restitution(&self) -> f64 {
        self.restitution_tangential
            .powf(self.omega0() / self.omega_d())
    }

    /// Box side L: given, or from the packing fraction (2D, L = sqrt(N pi r^2 / phi)) or the
    /// reduced length (1D, L = L' + N d).
    pub fn box_length(&self) -> f64 {
        if let Some(l) = self.box_length {
            return l;
        }
        let n = self.n_particles as f64;
        match (self.dim, self.packing_fraction, self.reduced_length) {
            (2, Some(phi), _) => (n * std::f64::consts::PI * self.radius.powi(2) / phi).sqrt(),
            (1, _, Some(lr)) => lr + n * self.diameter(),
            _ => f64::NAN,
        }
    }

    /// 2D packing fraction N pi r^2 / L^2, or 1D line fraction N d / L.
    pub fn fill_fraction(&self) -> f64 {
        let (n, l) = (self.n_particles as f64, self.box_length());
        if self.dim == 1 {
            n * self.diameter() / l
        } else {
            n * std::f64::consts::PI * self.radius.powi(2) / (l * l)
        }
    }

    /// Default time step: the largest power of ten not above t_c/10 (1e-6 s for the thesis
    /// constants, spec 1.5 [REC]).
    pub fn default_dt(&self) -> f64 {
        10f64.powf((self.contact_time() / 10.0).log10().floor())
    }

    /// The time step in use.
    pub fn dt(&self) -> f64 {
        self.dt.unwrap_or_else(|| self.default_dt())
    }

    /// Total steps of warm-up and of the sampled part.
    pub fn warmup_steps(&self) -> u64 {
        (self.warmup / self.dt()).round() as u64
    }
    pub fn duration_steps(&self) -> u64 {
        (self.duration / self.dt()).round() as u64
    }

    /// Warnings that do not stop a run: a time step coarser than t_c/10 (sec. 2.1.2).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let tc = self.contact_time();
        if self.dt() > tc / 10.0 {
            w.push(format!(
                "dt: {:e} s is coarser than t_c/10 = {:e} s (t_c = pi sqrt(m_12/k_s)); \
                 neighbour lists and the noise splitting lose accuracy",
                self.dt(),
                tc / 10.0
            ));
        }
        w
    }

    /// The sites of a 2D `square` or `hexagonal` bed (None for `uniform` and 1D): rows of
    /// discs at spacing d (1 + 1e-3), an even number of rows for the hexagonal one (odd rows
    /// would put two offset rows face to face across the boundary).
    pub fn lattice_sites(&self) -> Option<usize> {
        if self.dim != 2 || self.initial_layout == InitialLayout::Uniform {
            return None;
        }
        let l = self.box_length();
        let sp = self.diameter() * (1.0 + 1e-3);
        let hex = self.initial_layout == InitialLayout::Hexagonal;
        let per_row = (l / sp).floor() as usize;
        let pitch = if hex { sp * 3f64.sqrt() / 2.0 } else { sp };
        let rows = (l / pitch).floor() as usize;
        let rows = if hex { rows & !1 } else { rows };
        Some(per_row.saturating_mul(rows))
    }

    /// Every violated rule, each message starting with the field's name.
    pub fn validate(&self) -> Result<(), Vec<String>> {
        let mut e = Vec::new();
        self.check_particles(&mut e);
        self.check_box(&mut e);
        if e.is_empty() {
            self.check_initial_bed(&mut e);
        }
        self.check_run(&mut e);
        if e.is_empty() {
            Ok(())
        } else {
            Err(e)
        }
    }

    /// The rules of the dimension, the particles and their contacts (radius, mass, spring,
    /// noise, restitution, friction), into `e`.
    fn check_particles(&self, e: &mut Vec<String>) {
        if self.dim != 1 && self.dim != 2 {
            e.push(format!("dim: must be 1 or 2, got {}", self.dim));
        }
        if self.n_particles < 2 {
            e.push("n_particles: must be at least 2".into());
        }
        for (name, v) in [
            ("radius", self.radius),
            ("mass", self.mass),
            ("spring_constant", self.spring_constant),
        ] {
            if !positive(v) {
                e.push(format!("{name}: must be finite and > 0, got {v}"));
            }
        }
        if !(self.noise_strength.is_finite() && self.noise_strength >= 0.0) {
            e.push("noise_strength: must be finite and >= 0".into());
        }
        if !restitution_ok(self.restitution_normal) {
            e.push("restitution_normal: must lie in (0, 1]".into());
        }
        if !restitution_ok(self.restitution_tangential) {
            e.push("restitution_tangential: must lie in (0, 1]".into());
        }
        if self.dim == 1 && self.restitution_tangential != 1.0 {
            e.push("restitution_tangential: only 1 (none) in 1D".into());
        }
        if let Some(mu) = self.friction {
            if !(mu.is_finite() && mu >= 0.0) {
                e.push("friction: must be finite and >= 0".into());
            }
            if self.dim == 1 {
                e.push("friction: not used in 1D".into());
            }
        }
    }

    /// The rules of the box: exactly one of box_length, packing_fraction (2D) and
    /// reduced_length (1D), each in its range, into `e`.
    fn check_box(&self, e: &mut Vec<String>) {
        let given = [
            self.box_length.is_some(),
            self.packing_fraction.is_some(),
            self.reduced_length.is_some(),
        ]
        .iter()
        .filter(|&&b| b)
        .count();
        if given != 1 {
            e.push(
                "box_length: give exactly one of box_length, packing_fraction (2D), \
                 reduced_length (1D)"
                    .into(),
            );
        }
        if self.packing_fraction.is_some() && self.dim != 2 {
            e.push("packing_fraction: 2D only".into());
        }
        if self.reduced_length.is_some() && self.dim != 1 {
            e.push("reduced_length: 1D only".into());
        }
        if let Some(phi) = self.packing_fraction {
            if !(phi > 0.0 && phi < std::f64::consts::PI / (2.0 * 3f64.sqrt())) {
                e.push("packing_fraction: must lie in (0, pi/(2 sqrt 3))".into());
            }
        }
        if let Some(lr) = self.reduced_length {
            if !positive(lr) {
                e.push("reduced_length: must be > 0".into());
            }
        }
        if let Some(l) = self.box_length {
            if !positive(l) {
                e.push("box_length: must be > 0".into());
            }
        }
    }

    /// With every other rule of the particles and the box met: the box holds the particles
    /// (1D ring longer than N d, 2D box at least 3 diameters) and their initial layout, into `e`.
    fn check_initial_bed(&self, e: &mut Vec<String>) {
        let l = self.box_length();
        if self.dim == 1 && l <= self.n_particles as f64 * self.diameter() {
            e.push("box_length: 1D ring shorter than N d".into());
        }
        if self.dim == 2 && l < 3.0 * self.diameter() {
            e.push("box_length: must be at least 3 diameters".into());
        }
        // The initial layout must hold the discs (the run's start fails otherwise).
        let field = if self.packing_fraction.is_some() {
            "packing_fraction"
        } else {
            "box_length"
        };
        let phi = self.n_particles as f64 * std::f64::consts::PI * self.radius.powi(2) / (l * l);
        if let Some(sites) = self.lattice_sites() {
            if sites < self.n_particles {
                e.push(format!(
                    "{field}: {} discs do not fit the {:?} bed of this box ({sites} sites at spacing d (1 + 1e-3); packing fraction {phi:.3})",
                    self.n_particles, self.initial_layout
                ));
            }
        } else if self.dim == 2 && phi > UNIFORM_MAX_PACKING {
            e.push(format!(
                "{field}: packing fraction {phi:.3} is more than the uniform (random sequential) layout can reach ({UNIFORM_MAX_PACKING}: it jams at ~0.547): use initial_layout square or hexagonal"
            ));
        }
    }

    /// The rules of the run: the particle count's bound, the time step (below half the
    /// contact time), warmup, duration, sampling and the 1D layout, into `e`.
    fn check_run(&self, e: &mut Vec<String>) {
        if self.n_particles > MAX_PARTICLES {
            e.push(format!(
                "n_particles: at most {MAX_PARTICLES} (particle indices are 32-bit), got {}",
                self.n_particles
            ));
        }
        if let Some(dt) = self.dt {
            if !positive(dt) {
                e.push("dt: must be > 0".into());
            } else if positive(self.spring_constant)
                && positive(self.mass)
                && restitution_ok(self.restitution_normal)
            {
                if dt >= 0.5 * self.damped_contact_time() {
                    e.push("dt: must be below half the contact time pi/omega_d".into());
                }
            }
        }
        if !(self.warmup.is_finite() && self.warmup >= 0.0) {
            e.push("warmup: must be finite and >= 0".into());
        }
        if !(self.duration.is_finite() && self.duration >= 0.0) {
            e.push("duration: must be finite and >= 0".into());
        }
        if self.sample_every == 0 {
            e.push("sample_every: must be >= 1".into());
        }
        if self.dim == 1 && self.initial_layout != InitialLayout::Uniform {
            e.push("initial_layout: 1D supports only uniform (evenly spaced)".into());
        }
    }
}

/// Finite and > 0.
fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

/// A restitution coefficient: in (0, 1].
fn restitution_ok(x: f64) -> bool {
    x > 0.0 && x <= 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// gamma_n, gamma_t and pi/omega_d against the spec 1.1 table (printed to 4 significant
    /// figures: relative tolerance 1e-3).
    #[test]
    fn gamma_table_of_spec_1_1() {
        let rows = [
            (0.1, 3.512, 2.177, 2.31e-5),
            (0.3, 2.126, 1.138, 2.00e-5),
            (0.6, 0.9536, 0.4830, 1.89e-5),
            (0.9, 0.1991, 0.09963, 1.87e-5),
        ];
        for (eps, gn, gt, tcd) in rows {
            let c = RfmConfig {
                restitution_normal: eps,
                restitution_tangential: eps,
                ..RfmConfig::default()
            };
            assert!(
                (c.gamma_n() / gn - 1.0).abs() < 1e-3,
                "{eps} {}",
                c.gamma_n()
            );
            assert!(
                (c.gamma_t() / gt - 1.0).abs() < 1e-3,
                "{eps} {}",
                c.gamma_t()
            );
            assert!((c.damped_contact_time() / tcd - 1.0).abs() < 3e-3);
        }
        let c = RfmConfig::default();
        assert!((c.contact_time() / 1.867e-5 - 1.0).abs() < 1e-3);
        assert_eq!(c.dt(), 1e-6);
        assert!(c.warnings().is_empty());
        // eps = 0.1: effective eps_t = 0.1^(w0/wd) ~ 0.058 (spec 6.7).
        let c = RfmConfig {
            restitution_normal: 0.1,
            restitution_tangential: 0.1,
            ..RfmConfig::default()
        };
        assert!((c.effective_tangential_restitution() - 0.058).abs() < 1e-3);
    }

    #[test]
    fn geometry_and_validation() {
        let c = RfmConfig {
            box_length: None,
            packing_fraction: Some(0.353),
            ..RfmConfig::default()
        };
        assert!((c.box_length() - 0.2).abs() < 2e-4);
        let c1 = RfmConfig::thesis_1d(100, 0.5);
        assert!((c1.box_length() - 1.3).abs() < 1e-12);
        assert!(c1.validate().is_ok());
        assert!(RfmConfig::default().validate().is_ok());
        let bad = RfmConfig {
            dim: 3,
            restitution_normal: 0.0,
            packing_fraction: Some(0.3),
            sample_every: 0,
            ..RfmConfig::default()
        };
        let errs = bad.validate().unwrap_err();
        for field in [
            "dim:",
            "restitution_normal:",
            "box_length:",
            "sample_every:",
        ] {
            assert!(
                errs.iter().any(|e| e.starts_with(field)),
                "{field}: {errs:?}"
            );
        }
        let coarse = RfmConfig {
            dt: Some(4e-6),
            ..RfmConfig::default()
        };
        assert_eq!(coarse.warnings().len(), 1);
    }
}
