//! The low-rank method (paper section III.A, spec section 4), with speed groups.
//!
//! The majorant of the ordered species-pair rate, A_ik N_i N_k = pi/(4V) vmax_i
//! (sigma_i^2 + 2 sigma_i sigma_k + sigma_k^2) N_i N_k (42-43), has rank 3:
//! sum_r u_i^(r) w_k^(r) with u = N_i vmax_i (sigma_i^2, 2 sigma_i, 1) and w = N_k (1, sigma_k,
//! sigma_k^2). The w tables never change (counts are fixed); the u table changes only when a
//! speed bound does. Both are alias tables, so a species pair costs two 64-bit words.
//!
//! Speed groups tighten the majorant without changing the process: each species with at
//! least [`GROUP_MIN`] particles is split into a slow group (speeds below a threshold set at
//! each refresh, [`SLOW_FACTOR`] times the species' rms speed; its particles come first in the
//! species' range) and a fast group bounded by vmax_i. The u side then proposes (term, species,
//! group) with weight W_r sigma_i^p C_ig b_ig (C_ig >= N_ig a capacity fixed between
//! rebuilds, b_ig the group's bound) and a uniform slot of the group's capacity (a slot past
//! the group's size is a rejected trial); the w side proposes a uniform particle of species
//! k, whose bound b is that of the group it is in. The two orders of a pair together are
//! proposed at pi sigma^2 (b_a + b_b) / V, and accepted with |g| / (b_a + b_b), so the
//! accepted rate is pi sigma^2 |g| / V, the exact collision rate (36) integrated over e. For
//! the Table I gas about half of the trials of the plain method are needed; a collision
//! moves a particle between groups (a swap with the boundary particle) for a few percent of
//! the particles.
//!
//! The impact direction is then drawn with density ~ cos(theta) around g.

use serde::{Deserialize, Serialize};

use super::alias::Alias;
use super::collision::{collide, impact_direction};
use super::{prefetch, Candidate, DsmcSim, DsmcState, DsmcSystem, PhysicsError, RAISE_SLACK};
use crate::manifest::dsmc::DsmcMethod;

/// The three static tables over k: weights N_k, N_k sigma_k, N_k sigma_k^2.
pub fn static_tables(sys: &DsmcSystem) -> [Alias; 3] {
    let w = |p: i32| -> Vec<f64> {
        sys.species
            .iter()
            .map(|s| s.count as f64 * s.diameter.powi(p))
            .collect()
    };
    [Alias::new(&w(0)), Alias::new(&w(1)), Alias::new(&w(2))]
}

/// Species with fewer particles keep one group (bounded by vmax).
pub const GROUP_MIN: u64 = 64;
/// The slow group's bound, in units of the species' rms speed at the refresh: 1.6 v_rms
/// (~2.8 standard deviations of a Maxwell component, ~5 % of the particles fast) was the
/// fastest of 1.3-2.0 for the Table I gas (`scripts/bench-dsmc.sh`; flat within 3 % from 1.5
/// to 1.75).
pub const SLOW_FACTOR: f64 = 1.6;
/// Bit of a candidate's `i` that holds the proposed group.
pub const GROUP_BIT: u32 = 1 << 31;

/// A species' two speed groups (positions off..off + n_slow are slow, the rest fast).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SpeciesGroups {
    /// Particles in the slow group.
    pub n_slow: u64,
    /// Proposal capacities of the slow and the fast group (at least their sizes).
    pub cap: [u64; 2],
    /// Speed bound of the slow group; negative: one group (every particle is fast).
    pub thr: f64,
}

impl SpeciesGroups {
    /// One group: all `count` particles fast.
    pub fn single(count: u64) -> Self {
        SpeciesGroups {
            n_slow: 0,
            cap: [0, count],
            thr: -1.0,
        }
    }
}

/// Proposal capacity of a group of `n` particles: head-room so that particles moving in
/// rarely force a rebuild.
fn capacity(n: u64) -> u64 {
    n + (n / 32).max(16)
}

/// Slot j of the u table -> (term r, species i | group << 31), r-major, then species, group.
pub fn slot_tables(m: usize) -> (Vec<u8>, Vec<u32>) {
    let term = (0..6 * m).map(|j| (j / (2 * m)) as u8).collect();
    let species = (0..6 * m)
        .map(|j| {
            let rem = j % (2 * m);
            (rem / 2) as u32 | if rem % 2 == 1 { GROUP_BIT } else { 0 }
        })
        .collect();
    (term, species)
}

/// Weights of the u table: W_r sigma_i^p C_ig b_ig, laid out as [`slot_tables`].
pub fn dynamic_weights(
    sys: &DsmcSystem,
    vmax: &[f64],
    groups: &[SpeciesGroups],
    k_tables: &[Alias; 3],
) -> Vec<f64> {
    let m = sys.species.len();
    let mut w = Vec::with_capacity(6 * m);
    let factors = [|s: f64| s * s, |s: f64| 2.0 * s, |_s: f64| 1.0];
    for (r, f) in factors.iter().enumerate() {
        let wr = k_tables[r].total();
        for (i, sp) in sys.species.iter().enumerate() {
            let g = &groups[i];
            let fs = wr * f(sp.diameter);
            w.push(fs * g.cap[0] as f64 * g.thr.max(0.0));
            w.push(fs * g.cap[1] as f64 * vmax[i]);
        }
    }
    w
}

/// Consistency of a checkpoint's speed groups and particle ids with the run.
pub fn check_groups(sys: &DsmcSystem, st: &DsmcState) -> Result<(), String> {
    if sys.method != DsmcMethod::LowRank {
        return if st.groups.is_empty() && st.ids.is_empty() {
            Ok(())
        } else {
            Err("speed groups in a Bird run".into())
        };
    }
    if !st.groups.is_empty() {
        if st.groups.len() != sys.species.len() {
            return Err("one entry per species expected".into());
        }
        for (g, sp) in st.groups.iter().zip(&sys.species) {
            if g.n_slow > sp.count
                || g.cap[0] < g.n_slow
                || g.cap[1] < sp.count - g.n_slow
                || !g.thr.is_finite()
                || (g.thr < 0.0 && g.n_slow > 0)
            {
                return Err(format!("inconsistent group {g:?}"));
            }
        }
    }
    let n = st.vel.len();
    match (&sys.tamsd, st.ids.len()) {
        (None, 0) => Ok(()),
        (Some(_), len) if len == n => {
            let mut seen = vec![false; n];
            for &id in &st.ids {
                if id as usize >= n || std::mem::replace(&mut seen[id as usize], true) {
                    return Err("particle ids are not a permutation".into());
                }
            }
            Ok(())
        }
        _ => Err("particle ids do not match the observables".into()),
    }
}

/// Candidates tried per batch.
pub const BATCH: usize = 64;
/// Candidates drawn ahead: the batch being tried and two more in the prefetch pipeline.
pub const AHEAD: usize = 3 * BATCH;
/// Accepted collisions per batch at most (a batch ends when this many are pending).
const PENDING: usize = 24;

/// Per-particle speed bounds in one byte: level q bounds |v| for |v|^2 < lo 2^e (1 + (m+1)/8)
/// with q = 8 e + m (e the binary exponent of |v|^2 / lo, m its top three mantissa bits), so
/// a level costs no square root; level 255 is unbounded. The 1.2 MB of levels of the Table I
/// gas stay in the core's L2 cache where f32 bounds (4.8 MB) did not. Re-anchored at each
/// refresh; a bound only filters (it never changes a decision), so it is not checkpointed.
pub struct SpeedLadder {
    /// 1 / lo, a power of two (the scaling is exact).
    inv_lo: f64,
    /// |v| bound of each level (with a 1e-12 margin over rounding); lev[255] = infinity.
    lev: Box<[f64; 256]>,
}

impl SpeedLadder {
    /// A ladder whose top finite level is ~15 times (in |v|^2) above `vtop`^2.
    pub fn new(vtop: f64) -> Self {
        let v2 = vtop * vtop;
        let e = if v2 > 0.0 && v2.is_finite() {
            v2.log2().floor() as i32 - 28
        } else {
            0
        };
        let lo = 2f64.powi(e);
        let mut lev = Box::new([f64::INFINITY; 256]);
        for (q, l) in lev.iter_mut().enumerate().take(255) {
            let top = lo * 2f64.powi((q >> 3) as i32) * (1.0 + ((q & 7) + 1) as f64 / 8.0);
            *l = top.sqrt() * (1.0 + 1e-12);
        }
        SpeedLadder {
            inv_lo: 1.0 / lo,
            lev,
        }
    }

    /// The level of a velocity.
    #[inline(always)]
    pub fn level(&self, v: &[f64; 3]) -> u8 {
        let x = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) * self.inv_lo;
        if x < 1.0 {
            return 0;
        }
        if !x.is_finite() {
            // NaN or infinite: no bound (the exact test decides).
            return 255;
        }
        let bits = x.to_bits();
        let q = ((bits >> 52) as i64 - 1023) * 8 + ((bits >> 49) & 7) as i64;
        q.min(255) as u8
    }

    #[inline(always)]
    pub fn bound(&self, q: u8) -> f64 {
        self.lev[q as usize]
    }
}

/// Per-batch scratch of the low-rank loop (derived, never checkpointed).
#[derive(Default)]
pub struct BatchScratch {
    /// Indices (into the batch) of the candidates that pass the speed-bound filter, in order.
    pass: Vec<u32>,
    /// Per candidate of the batch: the position of particle a (its slot in its group).
    apos: Vec<u32>,
    /// Per candidate of the batch: u (b_a + b_b), the acceptance threshold on |g|.
    ubound: Vec<f64>,
}

/// The collisions accepted in the current batch: distinct particles, in time order; the first
/// `applied` of them have been applied.
struct Accepted {
    n: usize,
    applied: usize,
    cand: [Candidate; PENDING],
    t: [f64; PENDING],
    /// Position in the batch of each one's trial.
    trial: [u32; PENDING],
    /// 256-bit filter of their particles (bit p mod 256).
    bloom: [u64; 4],
}

impl Accepted {
    fn new() -> Self {
        Accepted {
            n: 0,
            applied: 0,
            cand: [Candidate::default(); PENDING],
            t: [0.0; PENDING],
            trial: [0; PENDING],
            bloom: [0; 4],
        }
    }

    #[inline(always)]
    fn bit(p: u32) -> (usize, u64) {
        ((p as usize >> 6) & 3, 1u64 << (p & 63))
    }

    /// Whether a candidate shares a particle with a collision accepted in this batch.
    #[inline(always)]
    fn touches(&self, c: &Candidate) -> bool {
        let ((wa, ba), (wb, bb)) = (Self::bit(c.a), Self::bit(c.b));
        if self.bloom[wa] & ba == 0 && self.bloom[wb] & bb == 0 {
            return false;
        }
        self.cand[..self.n]
            .iter()
            .any(|p| p.a == c.a || p.b == c.a || p.a == c.b || p.b == c.b)
    }

    #[inline(always)]
    fn push(&mut self, c: Candidate, t: f64, trial: usize) {
        self.cand[self.n] = c;
        self.t[self.n] = t;
        self.trial[self.n] = trial as u32;
        self.n += 1;
        for p in [c.a, c.b] {
            let (w, b) = Self::bit(p);
            self.bloom[w] |= b;
        }
    }
}

/// How a batch ended.
enum BatchEnd {
    /// Go on with the next batch.
    More,
    /// The run reached t_end.
    Done,
}

impl DsmcSim {
    #[inline(always)]
    fn draw_candidate(&mut self) -> Candidate {
        let ri = self.pair_i.sample(self.rng.u64());
        // SAFETY: the slot tables have one entry per (r, i, g) slot; r < 3.
        let (r, ig) = unsafe {
            (
                *self.slot_term.get_unchecked(ri) as usize,
                *self.slot_species.get_unchecked(ri),
            )
        };
        let i = (ig & !GROUP_BIT) as usize;
        let g = (ig >> 31) as usize;
        let k = unsafe { self.pair_k.get_unchecked(r) }.sample(self.rng.u64());
        let cap = self.st.groups[i].cap[g] as usize;
        let (ja, db) = self.rng.below_pair(cap, self.off[k + 1] - self.off[k]);
        let b = self.off[k] + db;
        let u = self.rng.f64();
        let gap = self.rng.f64_open0();
        let (start, _) = self.group_range(i, g);
        prefetch(self.sq.as_ptr().wrapping_add(start + ja));
        prefetch(self.sq.as_ptr().wrapping_add(b));
        Candidate {
            i: ig,
            k: k as u32,
            a: ja as u32,
            b: b as u32,
            u,
            gap,
        }
    }

    /// First position and size of group g of species i.
    #[inline(always)]
    fn group_range(&self, i: usize, g: usize) -> (usize, usize) {
        let gr = &self.st.groups[i];
        let n_slow = gr.n_slow as usize;
        let lo = self.off[i];
        if g == 0 {
            (lo, n_slow)
        } else {
            (lo + n_slow, self.off[i + 1] - lo - n_slow)
        }
    }

    /// Bound of group g of species i.
    #[inline(always)]
    fn group_bound(&self, i: usize, g: usize) -> f64 {
        if g == 0 {
            self.st.groups[i].thr
        } else {
            self.st.vmax[i]
        }
    }

    /// A candidate resolved against the current groups: the position of a (None for a slot
    /// past its group's size) and u (b_a + b_b).
    #[inline(always)]
    fn resolve(&self, c: &Candidate) -> (Option<usize>, f64) {
        let i = (c.i & !GROUP_BIT) as usize;
        let g = (c.i >> 31) as usize;
        let k = c.k as usize;
        let (start, n) = self.group_range(i, g);
        let b = c.b as usize;
        let gb = (b >= self.off[k] + self.st.groups[k].n_slow as usize) as usize;
        let ub = c.u * (self.group_bound(i, g) + self.group_bound(k, gb));
        let ja = c.a as usize;
        ((ja < n).then_some(start + ja), ub)
    }

    /// Fill the candidate buffer to [`AHEAD`] candidates, resolve those of the current batch
    /// (the first BATCH) and list the ones that the speed levels do not already reject
    /// (|g| <= |v_a| + |v_b| <= s_a + s_b). The buffer is a three-stage pipeline: a candidate
    /// gets its speed levels prefetched when drawn, its velocity lines prefetched when it
    /// moves into the second BATCH (if its possibly stale levels do not reject it), and is
    /// tried in the first.
    fn fill_and_filter(&mut self, moved: usize) {
        let before = self.batch.len();
        while self.batch.len() < AHEAD {
            let c = self.draw_candidate();
            self.batch.push(c);
        }
        // Candidates that entered stage 2: [2B - moved, 2B) (after a fresh start, all of it).
        let lo = if before == 0 {
            BATCH
        } else {
            2 * BATCH - moved.min(BATCH)
        };
        for j in lo..2 * BATCH {
            let c = self.batch[j];
            let (a, ub) = self.resolve(&c);
            let a = a.unwrap_or(0);
            let b = c.b as usize;
            // Branch-free: a rejected candidate prefetches particle 0 (a line kept hot).
            let keep =
                (ub < self.ladder.bound(self.sq[a]) + self.ladder.bound(self.sq[b])) as usize;
            let mask = keep.wrapping_neg();
            prefetch_record(&self.st.vel, a & mask);
            prefetch_record(&self.st.vel, b & mask);
        }
        let mut sc = std::mem::take(&mut self.scratch);
        sc.pass.clear();
        sc.pass.resize(BATCH, 0);
        sc.apos.resize(BATCH, 0);
        sc.ubound.resize(BATCH, 0.0);
        let mut np = 0;
        for j in 0..BATCH {
            let c = self.batch[j];
            let (a, ub) = self.resolve(&c);
            let b = c.b as usize;
            let ok = a.is_some_and(|a| {
                ub < self.ladder.bound(self.sq[a]) + self.ladder.bound(self.sq[b])
            });
            sc.apos[j] = a.unwrap_or(0) as u32;
            sc.ubound[j] = ub;
            // Branch-free compaction: always write, advance when passing.
            sc.pass[np] = j as u32;
            np += ok as usize;
        }
        sc.pass.truncate(np);
        self.scratch = sc;
    }

    /// Apply the accepted collisions not yet applied, in time order. A raised speed bound or
    /// a due refresh at collision j changes the proposal tables: the collisions accepted after
    /// j, the trials after j and the candidates drawn ahead are void (they came from the old
    /// tables; the decision to drop them depends only on the past). Returns the batch position
    /// of the trial of collision j when that happened. Particles are not moved between groups
    /// here (see [`relocate`](Self::relocate)).
    ///
    /// Impact directions come from their own stream (`geom`), drawn in collision order, so
    /// that when the collisions are applied (at the end of a batch or at an output time) does
    /// not change the trajectory.
    fn apply_accepted(&mut self, p: &mut Accepted) -> Option<usize> {
        let msd = !self.st.disp.is_empty();
        while p.applied < p.n {
            let q = p.applied;
            p.applied += 1;
            let c = p.cand[q];
            let (a, b) = (c.a as usize, c.b as usize);
            let (i, k) = (c.i as usize, c.k as usize);
            let va = self.st.vel[a];
            let vb = self.st.vel[b];
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let gn = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let (e, gne) = impact_direction(g, gn, &mut self.geom);
            let (ma, mb) = (self.sys.species[i].mass, self.sys.species[k].mass);
            let (mut na, mut nb) = (va, vb);
            let eps = self.eps.eps(i, k, gne);
            collide(&mut na, &mut nb, ma, mb, eps, e, gne);
            let t = p.t[q];
            if msd {
                for (j, v) in [(a, va), (b, vb)] {
                    let d = &mut self.st.disp[j];
                    let dt = t - d[3];
                    d[0] += v[0] * dt;
                    d[1] += v[1] * dt;
                    d[2] += v[2] * dt;
                    d[3] = t;
                }
            }
            self.st.t = t;
            self.st.vel[a] = na;
            self.st.vel[b] = nb;
            self.sq[a] = self.ladder.level(&na);
            self.sq[b] = self.ladder.level(&nb);
            self.st.collisions += 1;
            self.st.species_collisions[i] += 1;
            self.st.species_collisions[k] += 1;
            // Raise bounds that a new speed exceeds.
            let mut void = false;
            for (s, v) in [(i, na), (k, nb)] {
                let s2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                if s2 > self.st.vmax[s] * self.st.vmax[s] {
                    self.st.vmax[s] = s2.sqrt() * RAISE_SLACK;
                    void = true;
                }
            }
            if void {
                self.st.bound_raises += 1;
                self.rebuild_rates();
            }
            if self.refresh_due() {
                // Done at the end of the batch, after the particles have been relocated.
                self.refresh_pending = true;
                void = true;
            }
            if void {
                self.batch.clear();
                self.st.gap_prod = 1.0;
                self.st.gap_log = 0.0;
                p.n = p.applied;
                return Some(p.trial[q] as usize);
            }
        }
        None
    }

    /// Exchange the particles at positions x and y (velocity, level, displacement, id).
    fn swap_particles(&mut self, x: usize, y: usize) {
        if x == y {
            return;
        }
        self.st.vel.swap(x, y);
        self.sq.swap(x, y);
        if !self.st.disp.is_empty() {
            self.st.disp.swap(x, y);
        }
        if !self.st.ids.is_empty() {
            self.st.ids.swap(x, y);
            for pos in [x, y] {
                if let Some(q) = self.tracer_number(self.st.ids[pos]) {
                    self.tracer_pos[q] = pos as u32;
                }
            }
        }
    }

    /// The tracer number of a particle (by original index), if it is a tracer.
    fn tracer_number(&self, id: u32) -> Option<usize> {
        let plan = self.sys.tamsd.as_ref()?;
        let id = id as usize;
        let s = self.off.partition_point(|&o| o <= id) - 1;
        let t = id - self.off[s];
        (t < plan.tracers[s]).then(|| plan.tracers[..s].iter().sum::<usize>() + t)
    }

    /// Positions of the tracers, in tracer order (from `st.ids`).
    pub(super) fn tracer_positions(&self) -> Vec<u32> {
        let Some(plan) = &self.sys.tamsd else {
            return Vec::new();
        };
        if self.st.ids.is_empty() {
            return Vec::new();
        }
        let mut pos = vec![0u32; plan.n_tracers()];
        for (p, &id) in self.st.ids.iter().enumerate() {
            if let Some(q) = self.tracer_number(id) {
                pos[q] = p as u32;
            }
        }
        pos
    }

    /// Move the particles of the applied collisions of a batch into the group their speed
    /// belongs to (one swap with the particle at the group boundary). Returns whether a group
    /// outgrew its proposal capacity (the capacities are then reset and the rates rebuilt).
    fn relocate(&mut self, p: &Accepted) -> bool {
        let mut list = [(0usize, 0usize); 2 * PENDING];
        let mut n = 0;
        for c in &p.cand[..p.applied] {
            list[n] = (c.a as usize, c.i as usize);
            list[n + 1] = (c.b as usize, c.k as usize);
            n += 2;
        }
        let mut overflow = false;
        for q in 0..n {
            let (x, s) = list[q];
            let gr = self.st.groups[s];
            if gr.thr < 0.0 {
                continue;
            }
            let v = self.st.vel[x];
            let s2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            let boundary = self.off[s] + gr.n_slow as usize;
            let slow_now = x < boundary;
            let slow_wanted = s2 <= gr.thr * gr.thr;
            if slow_now == slow_wanted {
                continue;
            }
            // The boundary particle: the last slow one or the first fast one.
            let y = if slow_now { boundary - 1 } else { boundary };
            self.swap_particles(x, y);
            for e in &mut list[q + 1..n] {
                if e.0 == y {
                    e.0 = x;
                }
            }
            let gr = &mut self.st.groups[s];
            if slow_now {
                gr.n_slow -= 1;
            } else {
                gr.n_slow += 1;
            }
            let count = self.sys.species[s].count;
            if gr.n_slow > gr.cap[0] || count - gr.n_slow > gr.cap[1] {
                gr.cap = [capacity(gr.n_slow), capacity(count - gr.n_slow)];
                overflow = true;
            }
        }
        if overflow {
            self.rebuild_rates();
        }
        overflow
    }

    /// Split every species (with at least GROUP_MIN particles) into its slow and fast group
    /// at SLOW_FACTOR times its rms speed (after `refresh_bounds` set vmax), and set the
    /// capacities.
    pub(super) fn regroup(&mut self) {
        for s in 0..self.sys.species.len() {
            let count = self.sys.species[s].count;
            let (lo, hi) = (self.off[s], self.off[s + 1]);
            if count < GROUP_MIN {
                self.st.groups[s] = SpeciesGroups::single(count);
                continue;
            }
            let v2: f64 = self.st.vel[lo..hi]
                .iter()
                .map(|v| v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                .sum();
            let thr = (SLOW_FACTOR * (v2 / count as f64).sqrt()).min(self.st.vmax[s]);
            let thr2 = thr * thr;
            // Partition: slow particles first (Hoare, deterministic).
            let (mut x, mut y) = (lo, hi);
            loop {
                while x < y && speed2(&self.st.vel[x]) <= thr2 {
                    x += 1;
                }
                while x < y && speed2(&self.st.vel[y - 1]) > thr2 {
                    y -= 1;
                }
                if x + 1 >= y {
                    break;
                }
                self.swap_particles(x, y - 1);
                x += 1;
                y -= 1;
            }
            let n_slow = (x - lo) as u64;
            self.st.groups[s] = SpeciesGroups {
                n_slow,
                cap: [capacity(n_slow), capacity(count - n_slow)],
                thr,
            };
        }
    }

    /// One batch: fill and filter, then try the candidates in order. Accepted collisions are
    /// applied at the end of the batch or before an output time; their particles change
    /// groups at the end of the batch. A candidate on a particle of a collision accepted in
    /// this batch ends the batch before it (its filter result and maybe its velocities are
    /// stale), as does the PENDING-th acceptance; candidates not tried stay for the next
    /// batch, resolved and filtered again. Batches therefore end at the same trials whatever
    /// the output schedule, and so does the random stream. Adds the trials (void ones
    /// excluded) to `trials`.
    fn low_rank_batch(&mut self, trials: &mut u64) -> Result<BatchEnd, PhysicsError> {
        let moved = self.last_tried;
        self.fill_and_filter(moved);
        let mut p = Accepted::new();
        let sc = std::mem::take(&mut self.scratch);
        let mut next_pass = 0;
        let mut tried = BATCH;
        let mut end = BatchEnd::More;
        let mut void = None;
        for j in 0..BATCH {
            let mut c = self.batch[j];
            let (i, k) = ((c.i & !GROUP_BIT) as usize, c.k as usize);
            c.i = i as u32;
            c.a = sc.apos[j];
            let _ = k;
            if p.n > 0 && p.touches(&c) {
                tried = j;
                break;
            }
            self.st.gap_prod *= c.gap;
            if self.st.gap_prod < 1e-250 {
                self.st.gap_log += self.st.gap_prod.ln();
                self.st.gap_prod = 1.0;
            }
            if sc.pass.get(next_pass) != Some(&(j as u32)) {
                continue;
            }
            next_pass += 1;
            let (a, b) = (c.a as usize, c.b as usize);
            let va = self.st.vel[a];
            let vb = self.st.vel[b];
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
            let ub = sc.ubound[j];
            if ub * ub >= g2 {
                continue;
            }
            // Accepted: the collision happens at t_c; outputs before it see the old state.
            let t_last = if p.n > 0 { p.t[p.n - 1] } else { self.st.t };
            let t = self.gap_time_from(t_last);
            if self.next_event <= t {
                void = self.apply_accepted(&mut p);
                if void.is_some() {
                    break;
                }
                if self.outputs_before(t)? {
                    tried = j + 1;
                    end = BatchEnd::Done;
                    break;
                }
            }
            p.push(c, t, j);
            if p.n == PENDING {
                tried = j + 1;
                break;
            }
        }
        self.scratch = sc;
        if void.is_none() && !matches!(end, BatchEnd::Done) {
            void = self.apply_accepted(&mut p);
        }
        if self.relocate(&p) && void.is_none() && p.applied > 0 {
            // New capacities: the trials after the batch's last collision are void.
            self.batch.clear();
            self.st.gap_prod = 1.0;
            self.st.gap_log = 0.0;
            void = Some(p.trial[p.applied - 1] as usize);
        }
        if self.refresh_pending {
            self.refresh_pending = false;
            self.refresh_bounds();
        }
        match void {
            Some(j) => tried = j + 1,
            None if !matches!(end, BatchEnd::Done) => {
                self.batch.drain(..tried);
            }
            None => {}
        }
        *trials += tried as u64;
        self.last_tried = tried;
        Ok(end)
    }

    pub(super) fn advance_low_rank(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        let mut trials = 0u64;
        let result = loop {
            if self.rate <= 0.0 {
                break self.idle_to_end();
            }
            if trials >= max_trials {
                break Ok(false);
            }
            match self.low_rank_batch(&mut trials) {
                Ok(BatchEnd::More) => {}
                Ok(BatchEnd::Done) => break Ok(true),
                Err(e) => break Err(e),
            }
        };
        self.st.trials += trials;
        result
    }
}

#[inline(always)]
fn speed2(v: &[f64; 3]) -> f64 {
    v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
}

/// Prefetch the cache line(s) of a 24-byte velocity record (a quarter of them straddle two).
#[inline(always)]
fn prefetch_record(vel: &[[f64; 3]], j: usize) {
    let p = vel.as_ptr().wrapping_add(j) as *const u8;
    prefetch(p);
    prefetch(p.wrapping_add(23));
}
