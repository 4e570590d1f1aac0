//! Multiplicative cascade on a 2^n x 2^n grid (spec 3.4, thesis ch. 6).
//!
//! Level 0 is one cell of weight 1; every cell (i, j) of level n splits into the children
//! (2i+g, 2j+h), g, h in {0, 1}, with weights m a_{gh} / A (6.2)-(6.3). Variants (T 6.1):
//! UCP (a ~ U(0,1), A = sum of the four a: conserves the total weight), UnonCP (same a, A = 1),
//! symmetrised (a ~ U(0, 1/2) on the diagonal children, 1 - a on the others, A = 2 [REC]),
//! Meakin 1-4 (the fixed set p_1..p_4 randomly permuted onto the children at every split,
//! A = 1 [REC]).
//!
//! Structure factor (6.5): S(k) = <|sum_ij m_ij exp(i k.r_ij)|^2>, r_ij = (L/2^n)(i+1/2,
//! j+1/2), on the lattice k = 2 pi (p, q)/L of (4.3). At lattice k the sum is the 2D DFT of the
//! m field up to a phase (|p|, |q| <= 2^{n-1}), computed by FFT (rows, then columns). Each
//! realisation's S is averaged over every lattice vector of each exact shell p^2 + q^2 (as the
//! RFM S(k) is); the table gives the mean over realisations and its standard error. D_f from
//! the weighted least-squares fit of ln S = ln A - D_f ln k over a shell range (default
//! 1 <= |n| <= 2^{n-3}, spec 3.4 [REC]), weights from the standard errors.
//!
//! Placement (F 6.3): after the S(k) realisations, one more field is drawn; N discs of radius
//! r are placed by x, y ~ U(0, L), p ~ U(0, max m), accepted when p < m of the cell containing
//! (x, y) (i = floor(x / l_n), spec 6.23) and the disc overlaps no placed one (periodic). The
//! placed configuration's S(k) uses the RFM estimator (4.2) (`rfm::structure::SkAcc`), so it
//! compares directly with `rfm_structure_factor`.

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};

use crate::physics::SimError;
use crate::rng::{RngPosition, RunRng};

#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    Ucp,
    UnonCp,
    Symmetrised,
    /// Meakin 1..4.
    Meakin(u8),
}

/// T 6.1 probability sets of the Meakin processes.
pub const MEAKIN: [[f64; 4]; 4] = [
    [0.001, 0.15, 0.32, 0.53],
    [0.02, 0.32, 0.32, 0.34],
    [0.18, 0.21, 0.29, 0.31],
    [0.07, 0.26, 0.32, 0.36],
];

impl Variant {
    pub fn name(self) -> String {
        match self {
            Variant::Ucp => "ucp".into(),
            Variant::UnonCp => "unon_cp".into(),
            Variant::Symmetrised => "symmetrised".into(),
            Variant::Meakin(i) => format!("meakin{i}"),
        }
    }

    /// T 6.2: D_f and its error as printed (none for the symmetrised process).
    pub fn thesis_d_f(self) -> Option<(f64, f64)> {
        match self {
            Variant::Ucp => Some((1.602, 0.066)),
            Variant::UnonCp => Some((1.595, 0.064)),
            Variant::Symmetrised => None,
            Variant::Meakin(1) => Some((1.287, 0.084)),
            Variant::Meakin(2) => Some((1.596, 0.147)),
            Variant::Meakin(3) => Some((1.828, 0.233)),
            Variant::Meakin(4) => Some((1.689, 0.178)),
            Variant::Meakin(_) => None,
        }
    }

    /// The four children's factors a/A in the order (g, h) = (0,0), (0,1), (1,0), (1,1).
    #[inline]
    fn factors(self, rng: &mut RunRng) -> [f64; 4] {
        match self {
            Variant::Ucp => {
                let a = [rng.f64(), rng.f64(), rng.f64(), rng.f64()];
                let s = a[0] + a[1] + a[2] + a[3];
                if s > 0.0 {
                    [a[0] / s, a[1] / s, a[2] / s, a[3] / s]
                } else {
                    [0.25; 4]
                }
            }
            Variant::UnonCp => [rng.f64(), rng.f64(), rng.f64(), rng.f64()],
            Variant::Symmetrised => {
                let a = 0.5 * rng.f64();
                [0.5 * a, 0.5 * (1.0 - a), 0.5 * (1.0 - a), 0.5 * a]
            }
            Variant::Meakin(i) => {
                let mut p = MEAKIN[(i as usize).clamp(1, 4) - 1];
                // Fisher-Yates: a uniform permutation at every split.
                for k in (1..4).rev() {
                    let j = rng.below(k + 1);
                    p.swap(k, j);
                }
                p
            }
        }
    }
}

/// Resolved settings of the particle placement.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PlacementConfig {
    pub n_particles: u64,
    pub radius: f64,
    /// The run fails when the discs are not placed within this many attempts.
    pub max_attempts: u64,
    /// Largest |k| of the placed configuration's S(k) (units of 2 pi / L).
    pub k_max: f64,
}

/// Resolved settings of a cascade run.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CascadeConfig {
    pub level: u32,
    pub box_length: f64,
    pub variant: Variant,
    pub realisations: u64,
    /// Largest |k| of the field's S(k) (units of 2 pi / L), at most 2^{n-1}.
    pub k_max: f64,
    /// Shell range [|n|_lo, |n|_hi] of the D_f fit (units of 2 pi / L).
    pub fit_range: [f64; 2],
    pub placement: Option<PlacementConfig>,
}

/// `cascade_structure_factor` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SkRow {
    /// "field" (6.5) or "placement" (4.2 of the placed discs).
    pub source: String,
    pub n2: u64,
    pub k: f64,
    pub n_vectors: u64,
    pub n_realisations: u64,
    pub s_mean: f64,
    pub s_sem: Option<f64>,
}

/// `cascade_fit` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FitRow {
    pub source: String,
    pub variant: String,
    pub level: u32,
    pub k_lo: f64,
    pub k_hi: f64,
    pub n_shells: u32,
    pub d_f: Option<f64>,
    /// Formal WLS error scaled by sqrt(max(1, chi2_red)).
    pub d_f_err: Option<f64>,
    pub amplitude: Option<f64>,
    pub chi2_red: Option<f64>,
    pub d_f_thesis: Option<f64>,
    pub d_f_thesis_err: Option<f64>,
    /// Total weight sum_ij m_ij, mean and standard error over realisations (1 for UCP).
    pub weight_sum_mean: f64,
    pub weight_sum_sem: Option<f64>,
    /// Placement: attempts needed.
    pub attempts: Option<u64>,
}

/// `cascade_placement` row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct PlacementRow {
    pub particle: u32,
    pub x: f64,
    pub y: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CascadeOutput {
    pub structure_factor: Vec<SkRow>,
    pub fits: Vec<FitRow>,
    pub placement: Vec<PlacementRow>,
}

/// One cascade field of `level` levels into `out` (row-major, index i * 2^level + j),
/// `tmp` of the same size as scratch.
pub fn generate(variant: Variant, level: u32, rng: &mut RunRng, out: &mut Vec<f64>) {
    let g_final = 1usize << level;
    out.clear();
    out.resize(g_final * g_final, 0.0);
    out[0] = 1.0;
    // In place, coarsest level stored with stride: the level-l cell (i, j) lives at
    // out[(i * s) * G + j * s] with s = 2^{level - l}; splitting writes the four children at
    // stride s/2 (its own slot is overwritten last).
    for lev in 0..level {
        let s = 1usize << (level - lev);
        let h = s / 2;
        let g = 1usize << lev;
        for i in 0..g {
            for j in 0..g {
                let base = (i * s) * g_final + j * s;
                let m = out[base];
                let f = variant.factors(rng);
                out[base + h] = m * f[1];
                out[base + h * g_final] = m * f[2];
                out[base + h * g_final + h] = m * f[3];
                out[base] = m * f[0];
            }
        }
    }
}

/// Lattice vectors of the shells 0 < p^2 + q^2 <= cut: (shells n2 ascending, vectors per
/// shell, (flat FFT index, shell index) per vector) for a G x G grid.
pub fn shells(cut: u64, g: usize) -> (Vec<u64>, Vec<u64>, Vec<(u32, u32)>) {
    let m = (cut as f64).sqrt() as i64 + 1;
    let mut v = Vec::new();
    for p in -m..=m {
        for q in -m..=m {
            let n2 = (p * p + q * q) as u64;
            if n2 > 0 && n2 <= cut {
                let ip = p.rem_euclid(g as i64) as usize;
                let iq = q.rem_euclid(g as i64) as usize;
                v.push((n2, (ip * g + iq) as u32));
            }
        }
    }
    let mut n2: Vec<u64> = v.iter().map(|x| x.0).collect();
    n2.sort_unstable();
    n2.dedup();
    let mut count = vec![0u64; n2.len()];
    let idx = v
        .iter()
        .map(|&(s, i)| {
            let k = n2.binary_search(&s).expect("shell");
            count[k] += 1;
            (i, k as u32)
        })
        .collect();
    (n2, count, idx)
}

/// |DFT|^2 of a G x G real field by FFT: rows, transpose, rows (the result is indexed
/// [q * G + p], which the symmetric shells do not distinguish from [p * G + q]).
pub struct PowerSpectrum {
    g: usize,
    fft: Arc<dyn Fft<f64>>,
    a: Vec<Complex<f64>>,
    b: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl PowerSpectrum {
    pub fn new(g: usize) -> Self {
        let fft = FftPlanner::new().plan_fft_forward(g);
        let scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        PowerSpectrum {
            g,
            fft,
            a: vec![Complex::new(0.0, 0.0); g * g],
            b: vec![Complex::new(0.0, 0.0); g * g],
            scratch,
        }
    }

    /// |F(p, q)|^2 into `out` (index q * G + p for the field index i * G + j, or symmetric).
    pub fn power(&mut self, field: &[f64], out: &mut Vec<f64>) {
        let g = self.g;
        for (c, &m) in self.a.iter_mut().zip(field) {
            *c = Complex::new(m, 0.0);
        }
        self.fft
            .process_with_scratch(&mut self.a, &mut self.scratch);
        for i in 0..g {
            for j in 0..g {
                self.b[j * g + i] = self.a[i * g + j];
            }
        }
        self.fft
            .process_with_scratch(&mut self.b, &mut self.scratch);
        out.clear();
        out.extend(self.b.iter().map(|c| c.norm_sqr()));
    }
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct Placement {
    field: Vec<f64>,
    max_m: f64,
    xy: Vec<[f64; 2]>,
    attempts: u64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct State {
    cfg: CascadeConfig,
    rng: RngPosition,
    done: u64,
    /// Per shell: sums over realisations of the shell mean of |F|^2 and of its square.
    s_sum: Vec<f64>,
    s_sum2: Vec<f64>,
    /// Total weight: running mean and sum of squared deviations (Welford: the UCP weight is 1
    /// to rounding, and a sum of squares would lose the tiny variance).
    w_mean: f64,
    w_m2: f64,
    placement: Option<Placement>,
    failed: Option<String>,
}

pub struct CascadeRun {
    st: State,
    rng: RunRng,
    n2: Vec<u64>,
    n_vectors: Vec<u64>,
    index: Vec<(u32, u32)>,
    spectrum: PowerSpectrum,
    field: Vec<f64>,
    power: Vec<f64>,
    /// Placement cell grid (derived from the placed positions).
    grid: Vec<Vec<u32>>,
    nc: usize,
}

impl CascadeRun {
    pub fn new(cfg: CascadeConfig, seed: u64) -> Self {
        let cut = (cfg.k_max * cfg.k_max).floor() as u64;
        let g = 1usize << cfg.level;
        let (n2, _, _) = shells(cut, g);
        let st = State {
            rng: RunRng::new(seed).position(),
            done: 0,
            s_sum: vec![0.0; n2.len()],
            s_sum2: vec![0.0; n2.len()],
            w_mean: 0.0,
            w_m2: 0.0,
            placement: None,
            failed: None,
            cfg,
        };
        Self::from_state(st)
    }

    fn from_state(st: State) -> Self {
        let cut = (st.cfg.k_max * st.cfg.k_max).floor() as u64;
        let g = 1usize << st.cfg.level;
        let (n2, n_vectors, index) = shells(cut, g);
        let mut run = CascadeRun {
            rng: RunRng::restore(&st.rng),
            n2,
            n_vectors,
            index,
            spectrum: PowerSpectrum::new(g),
            field: Vec::new(),
            power: Vec::new(),
            grid: Vec::new(),
            nc: 0,
            st,
        };
        run.rebuild_grid();
        run
    }

    fn rebuild_grid(&mut self) {
        let (Some(pc), Some(pl)) = (&self.st.cfg.placement, &self.st.placement) else {
            return;
        };
        let l = self.st.cfg.box_length;
        let nc = ((l / (2.0 * pc.radius)).floor() as usize).max(1);
        self.nc = nc;
        self.grid = vec![Vec::new(); nc * nc];
        for (k, p) in pl.xy.iter().enumerate() {
            let c = self.cell(p[0], p[1]);
            self.grid[c].push(k as u32);
        }
    }

    fn cell(&self, x: f64, y: f64) -> usize {
        let l = self.st.cfg.box_length;
        let nc = self.nc;
        let cx = ((x / l * nc as f64) as usize).min(nc - 1);
        let cy = ((y / l * nc as f64) as usize).min(nc - 1);
        cx * nc + cy
    }

    pub fn state_bytes(&mut self) -> Vec<u8> {
        self.st.rng = self.rng.position();
        postcard::to_stdvec(&self.st).expect("state serialises")
    }

    pub fn from_state_bytes(cfg: CascadeConfig, bytes: &[u8]) -> Result<Self, SimError> {
        let st: State = postcard::from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        if st.cfg != cfg {
            return Err("checkpoint does not match the run's cascade parameters".into());
        }
        Ok(Self::from_state(st))
    }

    /// Realisations done.
    pub fn done(&self) -> u64 {
        self.st.done
    }

    pub fn progress(&self) -> f64 {
        let c = &self.st.cfg;
        let mut p = self.st.done as f64 / c.realisations.max(1) as f64;
        if let (Some(pc), Some(pl)) = (&c.placement, &self.st.placement) {
            p = 0.5 * p + 0.5 * pl.xy.len() as f64 / pc.n_particles.max(1) as f64;
        } else if c.placement.is_some() {
            p *= 0.5;
        }
        p.min(1.0)
    }

    /// Work units (~1 ns each) of one realisation.
    pub fn work_per_realisation(&self) -> u64 {
        30u64 << (2 * self.st.cfg.level)
    }

    /// Failure reason (placement not completed within max_attempts).
    pub fn failed(&self) -> Option<&str> {
        self.st.failed.as_deref()
    }

    /// Advance by about `work` units; true when the run is complete.
    pub fn advance(&mut self, work: u64) -> bool {
        let per = self.work_per_realisation();
        let mut budget = work;
        while self.st.done < self.st.cfg.realisations {
            self.realisation();
            budget = budget.saturating_sub(per);
            if budget == 0 {
                return false;
            }
        }
        if self.st.cfg.placement.is_none() || self.st.failed.is_some() {
            return true;
        }
        self.place(budget.max(1) / 16 + 1)
    }

    fn realisation(&mut self) {
        let c = &self.st.cfg;
        generate(c.variant, c.level, &mut self.rng, &mut self.field);
        let w: f64 = self.field.iter().sum();
        let n = (self.st.done + 1) as f64;
        let d = w - self.st.w_mean;
        self.st.w_mean += d / n;
        self.st.w_m2 += d * (w - self.st.w_mean);
        self.spectrum.power(&self.field, &mut self.power);
        let mut shell = vec![0.0; self.n2.len()];
        for &(i, s) in &self.index {
            shell[s as usize] += self.power[i as usize];
        }
        for (s, v) in shell.iter().enumerate() {
            let m = v / self.n_vectors[s] as f64;
            self.st.s_sum[s] += m;
            self.st.s_sum2[s] += m * m;
        }
        self.st.done += 1;
    }

    /// Up to `attempts` placement attempts; true when done (or failed).
    fn place(&mut self, attempts: u64) -> bool {
        let pc = self.st.cfg.placement.clone().expect("placement");
        let level = self.st.cfg.level;
        let l = self.st.cfg.box_length;
        if self.st.placement.is_none() {
            let mut field = Vec::new();
            generate(self.st.cfg.variant, level, &mut self.rng, &mut field);
            let max_m = field.iter().cloned().fold(0.0, f64::max);
            self.st.placement = Some(Placement {
                field,
                max_m,
                xy: Vec::new(),
                attempts: 0,
            });
            self.rebuild_grid();
        }
        let g = 1usize << level;
        let d2 = 4.0 * pc.radius * pc.radius;
        let nc = self.nc;
        for _ in 0..attempts {
            let pl = self.st.placement.as_ref().expect("placement");
            if pl.xy.len() as u64 >= pc.n_particles {
                return true;
            }
            if pl.attempts >= pc.max_attempts {
                self.st.failed = Some(format!(
                    "placed {} of {} discs in {} attempts (max_attempts)",
                    pl.xy.len(),
                    pc.n_particles,
                    pl.attempts
                ));
                return true;
            }
            let x = l * self.rng.f64();
            let y = l * self.rng.f64();
            let p = pl.max_m * self.rng.f64();
            let i = ((x / l * g as f64) as usize).min(g - 1);
            let j = ((y / l * g as f64) as usize).min(g - 1);
            let mut ok = p < pl.field[i * g + j];
            if ok {
                let c = self.cell(x, y);
                let (cx, cy) = ((c / nc) as i64, (c % nc) as i64);
                // Cells of side >= d: the 3 x 3 neighbourhood holds every disc within d (with
                // fewer than 3 cells per side it repeats cells, which is harmless).
                'outer: for dx in -1i64..=1 {
                    for dy in -1i64..=1 {
                        let cc = ((cx + dx).rem_euclid(nc as i64) as usize) * nc
                            + (cy + dy).rem_euclid(nc as i64) as usize;
                        for &k in &self.grid[cc] {
                            let q = pl.xy[k as usize];
                            let mut ddx = (x - q[0]).abs();
                            let mut ddy = (y - q[1]).abs();
                            ddx = ddx.min(l - ddx);
                            ddy = ddy.min(l - ddy);
                            if ddx * ddx + ddy * ddy < d2 {
                                ok = false;
                                break 'outer;
                            }
                        }
                    }
                }
            }
            let c = if ok { Some(self.cell(x, y)) } else { None };
            let pl = self.st.placement.as_mut().expect("placement");
            pl.attempts += 1;
            if let Some(c) = c {
                self.grid[c].push(pl.xy.len() as u32);
                pl.xy.push([x, y]);
            }
        }
        let pl = self.st.placement.as_ref().expect("placement");
        pl.xy.len() as u64 >= pc.n_particles
    }

    fn fit(&self, source: &str, rows: &[SkRow]) -> (Option<(f64, f64, f64, f64)>, u32) {
        let [lo, hi] = self.st.cfg.fit_range;
        let (mut x, mut y, mut w) = (Vec::new(), Vec::new(), Vec::new());
        for r in rows.iter().filter(|r| r.source == source) {
            let n = (r.n2 as f64).sqrt();
            if n < lo - 1e-9 || n > hi + 1e-9 || r.s_mean <= 0.0 {
                continue;
            }
            x.push(r.k.ln());
            y.push(r.s_mean.ln());
            w.push(match r.s_sem {
                Some(s) if s > 0.0 => (r.s_mean / s).powi(2),
                _ => 1.0,
            });
        }
        let n = x.len() as u32;
        (
            crate::math::fit::wls_line(&x, &y, &w)
                .map(|(a, b, _, sb, chi2)| (-b, sb * chi2.max(1.0).sqrt(), a.exp(), chi2)),
            n,
        )
    }

    pub fn finish(self) -> Result<CascadeOutput, SimError> {
        if let Some(f) = &self.st.failed {
            return Err(SimError::Failed(f.clone()));
        }
        let c = &self.st.cfg;
        let r = self.st.done;
        let tau = 2.0 * std::f64::consts::PI / c.box_length;
        let mut sk: Vec<SkRow> = (0..self.n2.len())
            .map(|s| {
                let (mean, sem) =
                    crate::math::stats::mean_sem_from_sums(r, self.st.s_sum[s], self.st.s_sum2[s]);
                SkRow {
                    source: "field".into(),
                    n2: self.n2[s],
                    k: tau * (self.n2[s] as f64).sqrt(),
                    n_vectors: self.n_vectors[s],
                    n_realisations: r,
                    s_mean: mean,
                    s_sem: sem,
                }
            })
            .collect();
        let wm = self.st.w_mean;
        let ws = (r >= 2).then(|| (self.st.w_m2 / ((r - 1) as f64) / r as f64).sqrt());
        let thesis = c.variant.thesis_d_f();
        let fit_row = |source: &str, f: Option<(f64, f64, f64, f64)>, n: u32, att| FitRow {
            source: source.into(),
            variant: c.variant.name(),
            level: c.level,
            k_lo: tau * c.fit_range[0],
            k_hi: tau * c.fit_range[1],
            n_shells: n,
            d_f: f.map(|f| f.0),
            d_f_err: f.map(|f| f.1),
            amplitude: f.map(|f| f.2),
            chi2_red: f.map(|f| f.3),
            d_f_thesis: thesis.map(|t| t.0),
            d_f_thesis_err: thesis.map(|t| t.1),
            weight_sum_mean: wm,
            weight_sum_sem: ws,
            attempts: att,
        };
        let (f, n) = self.fit("field", &sk);
        let mut fits = vec![fit_row("field", f, n, None)];
        let mut placement = Vec::new();
        if let (Some(pc), Some(pl)) = (&c.placement, &self.st.placement) {
            let flat: Vec<f64> = pl.xy.iter().flat_map(|p| [p[0], p[1]]).collect();
            let mut acc = crate::rfm::structure::SkAcc::new(crate::rfm::structure::SkConfig {
                n_max: pc.k_max,
                every: 1,
            });
            let mut w = acc.work();
            acc.add(&mut w, &flat, c.box_length);
            let start = sk.len();
            sk.extend(
                acc.rows(pl.xy.len(), c.box_length, 1)
                    .into_iter()
                    .map(|row| SkRow {
                        source: "placement".into(),
                        n2: row.n2,
                        k: row.k,
                        n_vectors: row.n_vectors,
                        n_realisations: 1,
                        s_mean: row.s,
                        s_sem: None,
                    }),
            );
            let (f, n) = self.fit("placement", &sk[start..]);
            let mut fr = fit_row("placement", f, n, Some(pl.attempts));
            let m: f64 = pl.field.iter().sum();
            fr.weight_sum_mean = m;
            fr.weight_sum_sem = None;
            fits.push(fr);
            placement = pl
                .xy
                .iter()
                .enumerate()
                .map(|(k, p)| PlacementRow {
                    particle: k as u32,
                    x: p[0],
                    y: p[1],
                })
                .collect();
        }
        Ok(CascadeOutput {
            structure_factor: sk,
            fits,
            placement,
        })
    }
}

/// S(k) of one field by the direct sum (6.5) over the cells, shell-averaged (reference for
/// the FFT; O(4^n n_k)).
pub fn direct_shell_power(field: &[f64], level: u32, l: f64, cut: u64) -> Vec<(u64, f64)> {
    let g = 1usize << level;
    let (n2, count, _) = shells(cut, g);
    let mut sums = vec![0.0; n2.len()];
    let m = (cut as f64).sqrt() as i64 + 1;
    let cell = l / g as f64;
    let tau = 2.0 * std::f64::consts::PI / l;
    for p in -m..=m {
        for q in -m..=m {
            let s2 = (p * p + q * q) as u64;
            if s2 == 0 || s2 > cut {
                continue;
            }
            let (mut re, mut im) = (0.0, 0.0);
            for i in 0..g {
                for j in 0..g {
                    let x = cell * (i as f64 + 0.5);
                    let y = cell * (j as f64 + 0.5);
                    let ph = tau * (p as f64 * x + q as f64 * y);
                    re += field[i * g + j] * ph.cos();
                    im += field[i * g + j] * ph.sin();
                }
            }
            let k = n2.binary_search(&s2).expect("shell");
            sums[k] += re * re + im * im;
        }
    }
    n2.iter()
        .zip(sums.iter().zip(&count))
        .map(|(&s, (&v, &c))| (s, v / c as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ucp_conserves_weight_and_fft_equals_direct_sum() {
        let mut rng = RunRng::new(5);
        let mut f = Vec::new();
        for _ in 0..20 {
            generate(Variant::Ucp, 6, &mut rng, &mut f);
            let s: f64 = f.iter().sum();
            assert!((s - 1.0).abs() < 1e-12, "UCP weight {s}");
            assert!(f.iter().all(|m| *m >= 0.0));
        }
        // Symmetrised: A = 2 also conserves the weight; Meakin 2 keeps the set's sum per split.
        generate(Variant::Symmetrised, 6, &mut rng, &mut f);
        assert!((f.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        generate(Variant::Meakin(2), 5, &mut rng, &mut f);
        assert!((f.iter().sum::<f64>() - 1.0f64.powi(5)).abs() < 1e-12);
        generate(Variant::Meakin(1), 5, &mut rng, &mut f);
        assert!((f.iter().sum::<f64>() - 1.001f64.powi(5)).abs() < 1e-12);
        // FFT vs direct sum (6.5) on a 16 x 16 grid, every shell up to the Nyquist |n| = 8.
        for v in [Variant::Ucp, Variant::UnonCp, Variant::Meakin(3)] {
            generate(v, 4, &mut rng, &mut f);
            let (n2, count, idx) = shells(64, 16);
            let mut ps = PowerSpectrum::new(16);
            let mut pw = Vec::new();
            ps.power(&f, &mut pw);
            let mut fft = vec![0.0; n2.len()];
            for &(i, s) in &idx {
                fft[s as usize] += pw[i as usize];
            }
            let direct = direct_shell_power(&f, 4, 0.7, 64);
            assert_eq!(direct.len(), n2.len());
            for (s, (d2, dv)) in direct.iter().enumerate() {
                assert_eq!(*d2, n2[s]);
                let fv = fft[s] / count[s] as f64;
                assert!(
                    (fv - dv).abs() < 1e-12 * dv.max(1e-6),
                    "{v:?} shell {d2}: {fv} vs {dv}"
                );
            }
        }
    }

    #[test]
    fn meakin_permutes_the_set() {
        let mut rng = RunRng::new(9);
        let mut seen = std::collections::BTreeSet::new();
        for _ in 0..500 {
            let f = Variant::Meakin(1).factors(&mut rng);
            let mut s = f;
            s.sort_by(|a, b| a.partial_cmp(b).unwrap());
            assert_eq!(s, MEAKIN[0]);
            seen.insert(f.iter().map(|x| (x * 1000.0) as i64).collect::<Vec<_>>());
        }
        assert_eq!(seen.len(), 24, "every permutation occurs");
    }

    #[test]
    fn placement_places_without_overlap_and_restores() {
        let cfg = CascadeConfig {
            level: 5,
            box_length: 0.1,
            variant: Variant::Ucp,
            realisations: 3,
            k_max: 16.0,
            fit_range: [1.0, 4.0],
            placement: Some(PlacementConfig {
                n_particles: 200,
                radius: 1.5e-3,
                max_attempts: 100_000_000,
                k_max: 20.0,
            }),
        };
        let mut a = CascadeRun::new(cfg.clone(), 4);
        while !a.advance(1 << 12) {}
        let mut b = CascadeRun::new(cfg.clone(), 4);
        for _ in 0..5 {
            b.advance(1 << 12);
            let bytes = b.state_bytes();
            b = CascadeRun::from_state_bytes(cfg.clone(), &bytes).unwrap();
        }
        while !b.advance(1 << 10) {}
        let (oa, ob) = (a.finish().unwrap(), b.finish().unwrap());
        assert_eq!(oa, ob);
        let p = &oa.placement;
        assert_eq!(p.len(), 200);
        let l = 0.1;
        for i in 0..p.len() {
            for j in 0..i {
                let mut dx = (p[i].x - p[j].x).abs();
                let mut dy = (p[i].y - p[j].y).abs();
                dx = dx.min(l - dx);
                dy = dy.min(l - dy);
                assert!(dx * dx + dy * dy >= 9e-6 * (1.0 - 1e-12), "{i} {j} overlap");
            }
        }
    }
}
