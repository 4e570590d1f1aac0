//! The physical system of a DSMC run, the engine's own configuration: species (mass,
//! diameter, count, initial temperature), volume, restitution, output schedule. The `dsmc`
//! model (`models::dsmc`) resolves it from the manifest's parameters.

use super::row_values::RowValueSet;
use crate::physics::SimError;
use crate::rng::RunRng;

/// The collision-pair selection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// The paper's low-rank method (section III.A): species pairs from a rank-3 majorant.
    LowRank,
    /// Bird's method (section III.B): uniform ordered pairs, one global majorant.
    Bird,
}

/// j t_end / grid, and t_end exactly for j = grid (also the lag of j steps).
pub fn grid_time(t_end: f64, grid: u64, j: u64) -> f64 {
    if j == grid {
        t_end
    } else {
        j as f64 * t_end / grid as f64
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct SpeciesInfo {
    pub mass: f64,
    pub diameter: f64,
    pub count: u64,
    pub initial_temperature: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct DsmcSystem {
    pub method: Method,
    pub species: Vec<SpeciesInfo>,
    pub volume: f64,
    pub restitution: RestitutionModel,
    pub t_end: f64,
    /// Sorted output times, 0 and t_end included.
    pub output_times: Vec<f64>,
    /// What the run records beyond temperatures and collision counts.
    pub observe: Observed,
    /// Refresh bounds every `refresh_every * N` collisions.
    pub refresh_every: f64,
    /// pi / (4 V): the low-rank rate constant of (43).
    pub rate_scale: f64,
}

/// What a run records beyond temperatures and collision counts (its observables), apart from
/// the rest of the configuration so that a system built by hand (tests, benches) names only
/// the observables it turns on (`Observed { msd: true, ..Default::default() }`) and does not
/// change when an observable is added.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Observed {
    /// Report <R_k^2(t)> (observable `msd`).
    pub msd: bool,
    /// The time-averaged MSD's tracers, grid and lags (observable `tamsd`).
    pub tamsd: Option<TamsdPlan>,
    /// The speed histograms at some output times (observable `velocity_distribution`).
    pub vdist: Option<VdistPlan>,
    /// The per-row values of `dsmc_species` recorded at every output (a2 of
    /// `velocity_distribution`, ...; see [`super::row_values`]).
    pub values: RowValueSet,
}

/// The time-averaged MSD of a run, resolved: which particles are tracers, the recording grid,
/// the lags.
#[derive(Clone, Debug, PartialEq)]
pub struct TamsdPlan {
    /// Number of intervals of [0, t_end]; positions are recorded at t_j = j t_end / grid,
    /// j = 0..=grid.
    pub grid: u64,
    /// Tracers of each species: its first min(tracers, N_k) particles.
    pub tracers: Vec<usize>,
    /// Lags in grid steps (sorted, distinct, 1 <= l < grid).
    pub lag_steps: Vec<u64>,
    /// The lags in time units, l t_end / grid (the `lag` column).
    pub lags: Vec<f64>,
}

impl TamsdPlan {
    pub fn n_tracers(&self) -> usize {
        self.tracers.iter().sum()
    }

    /// Time of grid point j.
    pub fn time(&self, t_end: f64, j: u64) -> f64 {
        grid_time(t_end, self.grid, j)
    }
}

/// The velocity distribution of a run, resolved: the histogram of the scaled speed at `times`
/// (the Sonine coefficient a2 of every species at every output time is the per-row value
/// [`super::RowValue::A2`]).
#[derive(Clone, Debug, PartialEq)]
pub struct VdistPlan {
    /// Output times (the very values of `output_times`) at which the histogram is recorded.
    pub times: Vec<f64>,
    /// Number of bins on [0, c_max).
    pub bins: u32,
    pub c_max: f64,
}

/// The restitution model of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RestitutionModel {
    Constant(f64),
    /// A kappa^(2/5) of the reference pair (m = 1, sigma = 1).
    Viscoelastic {
        a_kappa: f64,
    },
}

/// The restitution of a system as the theory sees it (the same pair scaling as the DSMC).
pub fn theory_restitution(
    r: &RestitutionModel,
    species: &[SpeciesInfo],
) -> crate::theory::restitution::PairRestitution {
    use crate::theory::restitution::PairRestitution;
    match *r {
        RestitutionModel::Constant(e) => PairRestitution::Constant(e),
        RestitutionModel::Viscoelastic { a_kappa } => {
            // eps_ki = F(a_ki g_n^(1/5)) with the DSMC's pair scaling; the `Scaled` form lets the
            // theory tabulate its Maxwell averages once.
            let a: Vec<Vec<f64>> = species
                .iter()
                .map(|sk| {
                    species
                        .iter()
                        .map(|si| {
                            super::viscoelastic::pair_a_kappa(
                                a_kappa,
                                sk.mass,
                                sk.diameter,
                                si.mass,
                                si.diameter,
                            )
                        })
                        .collect()
                })
                .collect();
            let table = super::viscoelastic::ViscoelasticTable::new();
            PairRestitution::scaled(a, 0.2, move |b| table.eps(b))
        }
    }
}

/// The species of the paper's power law: N_k = round(N_1 k^-theta), m_k = k,
/// sigma_k = k^(1/3), for every k up to the first with N_k < 1 (at most 10^6 species).
pub fn power_law_species(
    n1_count: u64,
    theta: f64,
    temperature: f64,
) -> Result<Vec<SpeciesInfo>, SimError> {
    let mut species = Vec::new();
    for k in 1u64.. {
        let count = (n1_count as f64 * (k as f64).powf(-theta)).round();
        if count < 1.0 {
            break;
        }
        species.push(SpeciesInfo {
            mass: k as f64,
            diameter: (k as f64).cbrt(),
            count: count as u64,
            initial_temperature: temperature,
        });
        if species.len() > 1_000_000 {
            return Err(SimError::Config(
                "power_law gives more than 1e6 species".into(),
            ));
        }
    }
    Ok(species)
}

/// Largest particle count a run may have (particle indices are 32-bit).
pub const MAX_PARTICLES: u64 = u32::MAX as u64 - 1;

impl DsmcSystem {
    /// The largest species diameter sigma_M.
    pub fn sigma_max(&self) -> f64 {
        self.species.iter().map(|s| s.diameter).fold(0.0, f64::max)
    }

    /// Whether per-particle displacements are kept (for `msd` and `tamsd`).
    pub fn displacements(&self) -> bool {
        self.observe.msd || self.observe.tamsd.is_some()
    }

    pub fn n_particles(&self) -> usize {
        self.species.iter().map(|s| s.count as usize).sum()
    }

    /// Number density n_k = N_k / V.
    pub fn density(&self, k: usize) -> f64 {
        self.species[k].count as f64 / self.volume
    }
}

/// Maxwell velocities; each species with two or more particles has zero momentum and exactly
/// its initial temperature. Single-particle species cannot have zero momentum: their momentum
/// is taken up by the species with two or more particles of largest total mass m_k N_k (which
/// is then rescaled about its mean to keep its temperature), so the total momentum is zero.
pub fn initial_velocities(sys: &DsmcSystem, rng: &mut RunRng) -> Vec<[f64; 3]> {
    let n = sys.n_particles();
    let mut vel = crate::memory::huge_vec(n, [0.0; 3]);
    let mut start = 0;
    let mut singles_p = [0.0; 3];
    let mut ranges = Vec::with_capacity(sys.species.len());
    for sp in &sys.species {
        let range = start..start + sp.count as usize;
        start = range.end;
        let sd = (sp.initial_temperature / sp.mass).sqrt();
        for v in &mut vel[range.clone()] {
            for c in v.iter_mut().take(3) {
                *c = sd * rng.normal();
            }
        }
        let vs = &mut vel[range.clone()];
        if vs.len() >= 2 {
            let mut mean = [0.0; 3];
            for v in vs.iter() {
                for d in 0..3 {
                    mean[d] += v[d];
                }
            }
            for m in &mut mean {
                *m /= vs.len() as f64;
            }
            for v in vs.iter_mut() {
                for d in 0..3 {
                    v[d] -= mean[d];
                }
            }
        }
        rescale(vs, [0.0; 3], sp.initial_temperature, sp.mass);
        if vs.len() == 1 {
            for d in 0..3 {
                singles_p[d] += sp.mass * vs[0][d];
            }
        }
        ranges.push(range);
    }
    if singles_p != [0.0; 3] {
        // The most massive species with >= 2 particles absorbs the singles' momentum.
        let target = (0..sys.species.len())
            .filter(|&s| sys.species[s].count >= 2)
            .max_by(|&a, &b| {
                let ma = sys.species[a].mass * sys.species[a].count as f64;
                let mb = sys.species[b].mass * sys.species[b].count as f64;
                ma.total_cmp(&mb)
            });
        if let Some(s) = target {
            let sp = &sys.species[s];
            let shift: Vec<f64> = singles_p
                .iter()
                .map(|p| -p / (sp.mass * sp.count as f64))
                .collect();
            let vs = &mut vel[ranges[s].clone()];
            for v in vs.iter_mut() {
                for d in 0..3 {
                    v[d] += shift[d];
                }
            }
            rescale(
                vs,
                [shift[0], shift[1], shift[2]],
                sp.initial_temperature,
                sp.mass,
            );
        }
    }
    vel
}

/// Scale the velocities about `mean` so that m <v^2> / 3 = t (when possible).
fn rescale(vs: &mut [[f64; 3]], mean: [f64; 3], t: f64, mass: f64) {
    let mut dev2 = 0.0;
    for v in vs.iter() {
        for d in 0..3 {
            dev2 += (v[d] - mean[d]) * (v[d] - mean[d]);
        }
    }
    let n = vs.len() as f64;
    let mean2 = mean.iter().map(|m| m * m).sum::<f64>();
    let want = 3.0 * t / mass - mean2;
    if dev2 <= 0.0 || want <= 0.0 {
        return;
    }
    let lambda = (want * n / dev2).sqrt();
    for v in vs.iter_mut() {
        for d in 0..3 {
            v[d] = mean[d] + lambda * (v[d] - mean[d]);
        }
    }
}
