//! The low-rank method (paper section III.A, spec section 4).
//!
//! The majorant of the ordered species-pair rate, A_ik N_i N_k = pi/(4V) vmax_i
//! (sigma_i^2 + 2 sigma_i sigma_k + sigma_k^2) N_i N_k (42-43), has rank 3:
//! sum_r u_i^(r) w_k^(r) with u = N_i vmax_i (sigma_i^2, 2 sigma_i, 1) and w = N_k (1, sigma_k,
//! sigma_k^2). The w tables never change (counts are fixed); the (r, i) table changes only when
//! a speed bound does. Both are alias tables, so a species pair costs two 64-bit words.
//!
//! A trial proposes an ordered particle pair and accepts it with |g| / (vmax_i + vmax_k): the
//! two orders of a pair together are proposed at pi sigma^2 (vmax_i + vmax_k) / V, so the
//! accepted rate is pi sigma^2 |g| / V, the exact collision rate (36) integrated over e.
//! The impact direction is then drawn with density ~ cos(theta) around g.

use super::alias::Alias;
use super::collision::{collide, impact_direction};
use super::{prefetch, Candidate, DsmcSim, DsmcSystem, PhysicsError, RAISE_SLACK};

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

/// Weights of the (r, i) table: W_r u_i^(r), laid out r-major.
pub fn dynamic_weights(sys: &DsmcSystem, vmax: &[f64], k_tables: &[Alias; 3]) -> Vec<f64> {
    let m = sys.species.len();
    let mut w = Vec::with_capacity(3 * m);
    let factors = [|s: f64| s * s, |s: f64| 2.0 * s, |_s: f64| 1.0];
    for (r, f) in factors.iter().enumerate() {
        let wr = k_tables[r].total();
        for (i, sp) in sys.species.iter().enumerate() {
            w.push(wr * sp.count as f64 * vmax[i] * f(sp.diameter));
        }
    }
    w
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
        // SAFETY: the slot tables have one entry per (r, i) slot; r < 3.
        let (r, i) = unsafe {
            (
                *self.slot_term.get_unchecked(ri) as usize,
                *self.slot_species.get_unchecked(ri) as usize,
            )
        };
        let k = unsafe { self.pair_k.get_unchecked(r) }.sample(self.rng.u64());
        let (da, db) = self
            .rng
            .below_pair(self.off[i + 1] - self.off[i], self.off[k + 1] - self.off[k]);
        let (a, b) = (self.off[i] + da, self.off[k] + db);
        let u = self.rng.f64() * (self.st.vmax[i] + self.st.vmax[k]);
        let gap = self.rng.f64_open0();
        prefetch(self.sq.as_ptr().wrapping_add(a));
        prefetch(self.sq.as_ptr().wrapping_add(b));
        Candidate {
            i: i as u32,
            k: k as u32,
            a: a as u32,
            b: b as u32,
            u,
            gap,
        }
    }

    /// Fill the candidate buffer to [`AHEAD`] candidates and list those of the current batch
    /// (the first BATCH) that the speed bounds do not already reject
    /// (|g| <= |v_a| + |v_b| <= s_a + s_b). The buffer is a three-stage pipeline: a candidate
    /// gets its speed bounds prefetched when drawn, its velocity lines prefetched when it
    /// moves into the second BATCH (if its possibly stale bounds do not reject it), and is
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
        for c in &self.batch[lo..2 * BATCH] {
            let (a, b) = (c.a as usize, c.b as usize);
            // Branch-free: a rejected candidate prefetches particle 0 (a line kept hot).
            let keep =
                (c.u < self.ladder.bound(self.sq[a]) + self.ladder.bound(self.sq[b])) as usize;
            let mask = keep.wrapping_neg();
            prefetch_record(&self.st.vel, a & mask);
            prefetch_record(&self.st.vel, b & mask);
        }
        let pass = &mut self.scratch.pass;
        pass.clear();
        pass.resize(BATCH, 0);
        let mut np = 0;
        for (j, c) in self.batch[..BATCH].iter().enumerate() {
            let (a, b) = (c.a as usize, c.b as usize);
            let s = self.ladder.bound(self.sq[a]) + self.ladder.bound(self.sq[b]);
            // Branch-free compaction: always write, advance when passing.
            pass[np] = j as u32;
            np += (c.u < s) as usize;
        }
        pass.truncate(np);
    }

    /// Apply the accepted collisions not yet applied, in time order. A raised speed bound or
    /// a refresh at collision j changes the proposal tables: the collisions accepted after j,
    /// the trials after j and the candidates drawn ahead are void (they came from the old
    /// tables; the decision to drop them depends only on the past). Returns the batch position
    /// of the trial of collision j when that happened.
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
                self.refresh_bounds();
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

    /// One batch: fill and filter, then try the candidates in order. Accepted collisions are
    /// applied at the end of the batch or before an output time. A candidate on a particle of
    /// a collision accepted in this batch ends the batch before it (its filter result and
    /// maybe its velocities are stale), as does the PENDING-th acceptance; candidates not
    /// tried stay for the next batch, filtered again. Batches therefore end at the same trials
    /// whatever the output schedule, and so does the random stream. Adds the trials (void ones
    /// excluded) to `trials`.
    fn low_rank_batch(&mut self, trials: &mut u64) -> Result<BatchEnd, PhysicsError> {
        let moved = self.last_tried;
        self.fill_and_filter(moved);
        let mut p = Accepted::new();
        let pass = std::mem::take(&mut self.scratch.pass);
        let mut next_pass = 0;
        let mut tried = BATCH;
        let mut end = BatchEnd::More;
        let mut void = None;
        for j in 0..BATCH {
            let c = self.batch[j];
            if p.n > 0 && p.touches(&c) {
                tried = j;
                break;
            }
            self.st.gap_prod *= c.gap;
            if self.st.gap_prod < 1e-250 {
                self.st.gap_log += self.st.gap_prod.ln();
                self.st.gap_prod = 1.0;
            }
            if pass.get(next_pass) != Some(&(j as u32)) {
                continue;
            }
            next_pass += 1;
            let (a, b) = (c.a as usize, c.b as usize);
            let va = self.st.vel[a];
            let vb = self.st.vel[b];
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
            if c.u * c.u >= g2 {
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
        self.scratch.pass = pass;
        if void.is_none() && !matches!(end, BatchEnd::Done) {
            void = self.apply_accepted(&mut p);
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

/// Prefetch the cache line(s) of a 24-byte velocity record (a quarter of them straddle two).
#[inline(always)]
fn prefetch_record(vel: &[[f64; 3]], j: usize) {
    let p = vel.as_ptr().wrapping_add(j) as *const u8;
    prefetch(p);
    prefetch(p.wrapping_add(23));
}
