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
//! each refresh, [`GROUP_FACTORS`] times the species' rms speed; its particles come first in the
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

use super::alias::{Alias, AliasStack};
use super::collision::{collide_impulse, impact_impulse};
use super::system::Method;
use super::{
    drift, prefetch, prefetch_l1, Candidate, DsmcSim, DsmcState, DsmcSystem, PhysicsError,
    RAISE_SLACK,
};
use crate::physics::SimError;

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
/// Speed groups per species.
pub const GROUPS: usize = 2;
/// Upper speed bounds of the groups below the top one, in units of the species' rms speed at
/// the refresh (the top group is bounded by vmax). With two groups, 1.6 v_rms (2.77 standard
/// deviations of a component) puts ~95 % of a Maxwell gas in the slow group. (Three groups,
/// [0.98, 1.59]: ~60 %, ~33 % and ~7 %, 27 % fewer trials for Table I but slower, the group
/// moves costing more than the trials saved; see README, Performance.)
pub const GROUP_FACTORS: [f64; GROUPS - 1] = [1.6];
/// Candidate's `i` holds the proposed group from this bit on.
pub const GROUP_SHIFT: u32 = 30;
/// Mask of the species in a candidate's `i`.
pub const SPECIES_MASK: u32 = (1 << GROUP_SHIFT) - 1;

/// A species' speed groups: group g holds the n[g] particles after those of the groups below
/// it (the species' range is ordered by group).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SpeciesGroups {
    /// Particles in each group.
    pub n: [u64; GROUPS],
    /// Proposal capacities of the groups (at least their sizes).
    pub cap: [u64; GROUPS],
    /// Speed bounds of the groups below the top one (nondecreasing); negative: one group
    /// (every particle in the top group).
    pub thr: [f64; GROUPS - 1],
}

impl SpeciesGroups {
    /// One group: all `count` particles in the top group.
    pub fn single(count: u64) -> Self {
        let mut n = [0; GROUPS];
        n[GROUPS - 1] = count;
        SpeciesGroups {
            n,
            cap: n,
            thr: [-1.0; GROUPS - 1],
        }
    }

    /// Whether the species is split.
    pub fn split(&self) -> bool {
        self.thr[0] >= 0.0
    }

    /// Speed bound of group g (the top group's is the species' vmax; negative for the
    /// unused lower groups of an unsplit species).
    #[inline(always)]
    pub fn bound(&self, g: usize, vmax: f64) -> f64 {
        if g + 1 < GROUPS {
            self.thr[g]
        } else {
            vmax
        }
    }

    /// The group a squared speed belongs to.
    #[inline(always)]
    pub fn group_of(&self, s2: f64) -> usize {
        self.thr.iter().filter(|&&t| s2 > t * t).count()
    }
}

/// A group as the hot loop reads it (derived from the species' [`SpeciesGroups`], offsets
/// and vmax; index 2 i + g).
#[derive(Clone, Copy, Debug, Default)]
pub struct GroupInfo {
    pub start: u32,
    pub n: u32,
    pub cap: u32,
    /// The position of the group's slot 0 ([`slot_position`]; fixed by the species' range).
    pub anchor: u32,
    pub bound: f64,
}

/// The position that slot `ja` of group g of the species whose range is `lo..hi` names (the
/// slot is valid while that position is in the group: `position - start < n`, wrapping). The
/// slots of every group but the first count down from the range's end: so that positions
/// prefetched a batch ahead mostly stay right when group sizes change, and so that a slot
/// names the same position whatever the group sizes (the queue holds positions). Wrapping
/// 32-bit arithmetic: a bijection between slots and positions for each group.
#[inline(always)]
pub fn slot_position(anchor: u32, g: usize, ja: u32) -> u32 {
    if g >= 1 {
        anchor.wrapping_sub(ja)
    } else {
        anchor.wrapping_add(ja)
    }
}

// With more groups a middle group's slots would count down from its moving upper end: the
// anchors below are those of two groups.
const _: () = assert!(GROUPS == 2);

/// The anchor (slot 0's position) of group g of the species with range `lo..hi`.
#[inline(always)]
pub fn group_anchor(lo: usize, hi: usize, g: usize) -> u32 {
    if g >= 1 {
        (hi as u32).wrapping_sub(1)
    } else {
        lo as u32
    }
}

/// A candidate as checkpoints hold it (a slot of its group in `a`) from one as the queue
/// holds it (the position the slot names), and back.
pub fn candidate_slot(c: &Candidate, off: &[usize]) -> Candidate {
    let (i, g) = ((c.i & SPECIES_MASK) as usize, (c.i >> GROUP_SHIFT) as usize);
    let anchor = group_anchor(off[i], off[i + 1], g);
    let a = if g >= 1 {
        anchor.wrapping_sub(c.a)
    } else {
        c.a.wrapping_sub(anchor)
    };
    Candidate { a, ..*c }
}

/// The inverse of [`candidate_slot`] (for a candidate whose species are of the run).
pub fn candidate_position(c: &Candidate, off: &[usize]) -> Candidate {
    let (i, g) = ((c.i & SPECIES_MASK) as usize, (c.i >> GROUP_SHIFT) as usize);
    let a = slot_position(group_anchor(off[i], off[i + 1], g), g, c.a);
    Candidate { a, ..*c }
}

/// Proposal capacity of a group of `n` particles: head-room so that particles moving in
/// rarely force a rebuild.
fn capacity(n: u64) -> u64 {
    // Positions and capacities are 32-bit (a run has at most u32::MAX - 1 particles).
    (n + (n / 64).max(8)).min(u32::MAX as u64)
}

/// The static tables of a candidate's draw, laid out so that each step of the draw reads one
/// entry (built once per run).
pub struct DrawTables {
    /// Slot j of the u table (r-major, then species, then group) decoded: species i with its
    /// group g from GROUP_SHIFT in the low half, r M (term r's first slot in `k`) in the high.
    slot: Vec<u64>,
    /// The k tables of the terms r = 0, 1, 2.
    k: AliasStack,
    /// Species k's particle positions: the first in the low half, the count in the high.
    range: Vec<u64>,
}

impl DrawTables {
    /// The tables for the k tables of [`static_tables`] and the species' offsets (M + 1).
    pub fn new(k_tables: &[Alias; 3], off: &[usize]) -> Self {
        let m = off.len() - 1;
        // (No species: nothing is ever drawn.)
        let k = AliasStack::new(k_tables).unwrap_or_default();
        debug_assert!(m == 0 || k.table_len() == m);
        let per_term = GROUPS * m;
        let slot = (0..3 * per_term)
            .map(|j| {
                let (r, rem) = (j / per_term, j % per_term);
                let ig = (rem / GROUPS) as u64 | ((rem % GROUPS) as u64) << GROUP_SHIFT;
                ig | ((r * m) as u64) << 32
            })
            .collect();
        // Positions are 32-bit (a run has at most u32::MAX - 1 particles).
        let range = off
            .windows(2)
            .map(|w| w[0] as u32 as u64 | ((w[1] - w[0]) as u32 as u64) << 32)
            .collect();
        DrawTables { slot, k, range }
    }
}

/// Weights of the u table: W_r sigma_i^p C_ig b_ig, laid out as [`DrawTables`]'s slots.
pub fn dynamic_weights(
    sys: &DsmcSystem,
    vmax: &[f64],
    groups: &[SpeciesGroups],
    k_tables: &[Alias; 3],
) -> Vec<f64> {
    let m = sys.species.len();
    let mut w = Vec::with_capacity(3 * GROUPS * m);
    let factors = [|s: f64| s * s, |s: f64| 2.0 * s, |_s: f64| 1.0];
    for (r, f) in factors.iter().enumerate() {
        let wr = k_tables[r].total();
        for (i, sp) in sys.species.iter().enumerate() {
            let gr = &groups[i];
            let fs = wr * f(sp.diameter);
            for g in 0..GROUPS {
                w.push(fs * gr.cap[g] as f64 * gr.bound(g, vmax[i]).max(0.0));
            }
        }
    }
    w
}

/// Consistency of a checkpoint's speed groups and particle ids with the run.
pub fn check_groups(sys: &DsmcSystem, st: &DsmcState) -> Result<(), SimError> {
    if sys.method != Method::LowRank {
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
            let total = g.n.iter().try_fold(0u64, |a, &n| a.checked_add(n));
            let ok = total == Some(sp.count)
                && g.cap.iter().zip(&g.n).all(|(c, n)| c >= n)
                && g.cap.iter().all(|&c| c <= u32::MAX as u64)
                && g.thr.iter().all(|t| t.is_finite())
                && g.thr.windows(2).all(|w| w[0] <= w[1])
                && (g.split() || g.n[..GROUPS - 1].iter().all(|&n| n == 0));
            if !ok {
                return Err(SimError::State(format!("inconsistent groups {g:?}")));
            }
        }
    }
    let n = st.vel.len();
    match (&sys.observe.tamsd, st.ids.len()) {
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

/// Candidates tried per batch (16-32 were fastest for Table I; 64 4 % and 128 15 % slower).
pub const BATCH: usize = 32;
/// Candidates drawn ahead: the batch being tried and the next one (whose first candidates'
/// velocity lines are prefetched while this one is tried, [`LEAD`] trials ahead).
pub const AHEAD: usize = 2 * BATCH;
/// How many trials ahead a candidate's velocity lines are prefetched (at most BATCH: the
/// candidates of the batch after the next are not drawn yet). 20 rather than 32: CPU time
/// 0.978x for Table I (12: 0.979x; docs/performance.md).
const LEAD: usize = 20;
const _: () = assert!(LEAD <= BATCH);
/// Capacity of the candidate queue (a power of two, at least AHEAD).
const QUEUE: usize = 128;
const _: () = assert!(QUEUE.is_power_of_two() && QUEUE >= AHEAD);

/// The candidates drawn and not yet tried, oldest first (a ring: trying a batch moves the
/// head, nothing is copied).
pub struct CandidateQueue {
    buf: Box<[Candidate; QUEUE]>,
    head: usize,
    len: usize,
}

impl CandidateQueue {
    pub fn from_slice(cs: &[Candidate]) -> Self {
        let mut q = CandidateQueue {
            buf: Box::new([Candidate::default(); QUEUE]),
            head: 0,
            len: 0,
        };
        for &c in cs.iter().take(AHEAD) {
            q.push(c);
        }
        q
    }

    #[inline(always)]
    pub fn len(&self) -> usize {
        self.len
    }

    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    #[inline(always)]
    fn push(&mut self, c: Candidate) {
        debug_assert!(self.len < QUEUE);
        self.buf[(self.head + self.len) & (QUEUE - 1)] = c;
        self.len += 1;
    }

    /// The candidate j places behind the oldest (j < len).
    #[inline(always)]
    fn get(&self, j: usize) -> Candidate {
        debug_assert!(j < self.len);
        self.buf[(self.head + j) & (QUEUE - 1)]
    }

    /// Drop the oldest n.
    #[inline(always)]
    fn advance(&mut self, n: usize) {
        debug_assert!(n <= self.len);
        self.head = (self.head + n) & (QUEUE - 1);
        self.len -= n;
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    pub fn to_vec(&self) -> Vec<Candidate> {
        (0..self.len).map(|j| self.get(j)).collect()
    }
}

impl Candidate {
    /// A low-rank candidate as the queue holds it: species i with its proposed group (bits
    /// from GROUP_SHIFT), the position `a` that the drawn slot of the group names
    /// ([`slot_position`]), species k and particle b of it.
    #[inline(always)]
    fn low_rank(ig: u32, k: usize, a: u32, b: usize, u: f64, gap: f64) -> Self {
        Candidate {
            i: ig,
            k: k as u32,
            a,
            b: b as u32,
            u,
            gap,
        }
    }
}

/// Displacement updates of applied collisions not yet written (particle position, velocity
/// before the collision, collision time), in collision order.
pub struct PendingDisplacements {
    buf: [(usize, [f64; 3], f64); 2 * PENDING_COLLISIONS],
    n: usize,
}

/// Collisions whose displacement updates may wait.
const PENDING_COLLISIONS: usize = 16;

impl Default for PendingDisplacements {
    fn default() -> Self {
        PendingDisplacements {
            buf: [(0, [0.0; 3], 0.0); 2 * PENDING_COLLISIONS],
            n: 0,
        }
    }
}

impl PendingDisplacements {
    #[inline(always)]
    fn push(&mut self, a: (usize, [f64; 3], f64), b: (usize, [f64; 3], f64)) {
        self.buf[self.n] = a;
        self.buf[self.n + 1] = b;
        self.n += 2;
    }

    #[inline(always)]
    fn full(&self) -> bool {
        self.n == self.buf.len()
    }

    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The pending updates, in order; the list is empty afterwards.
    fn take(&mut self) -> &[(usize, [f64; 3], f64)] {
        let n = std::mem::replace(&mut self.n, 0);
        &self.buf[..n]
    }
}

/// How a batch ended.
enum BatchEnd {
    /// Go on with the next batch.
    More,
    /// The run reached t_end.
    Done,
    /// A collision changed the proposal tables (within a batch only).
    Void,
}

/// What an accepted collision led to.
enum Accepted {
    /// Go on with the batch.
    Go,
    /// Its time is past the run's end: the run is done (the collision is not applied).
    Done,
    /// It changed the proposal tables: the queued candidates are void.
    Void,
}

impl DsmcSim {
    /// Draw the next candidate: five words, (term r, species i, group g) from the u table,
    /// species k from table r, the slot of a in its group and particle b of k (the 32-bit
    /// halves of one word, Lemire's method), the acceptance uniform and the gap uniform.
    #[inline(always)]
    fn draw_candidate(&mut self) -> Candidate {
        let w = self.rng.window(5);
        let (w0, w1, w2, w3, w4) = (w[0], w[1], w[2], w[3], w[4]);
        let ri = self.pair_i.sample(w0);
        let t = &self.draw;
        // SAFETY: the slot table has one entry per (r, i, g) slot of pair_i; its high halves
        // are starts of k tables; the k tables draw species; gtab has GROUPS entries per
        // species.
        let slot = unsafe { *t.slot.get_unchecked(ri) };
        let ig = slot as u32;
        let i = (ig & SPECIES_MASK) as usize;
        let g = (ig >> GROUP_SHIFT) as usize;
        let k = t.k.sample((slot >> 32) as usize, w1);
        let ga = unsafe { *self.gtab.get_unchecked(GROUPS * i + g) };
        let range = unsafe { *t.range.get_unchecked(k) };
        let (ok, nk) = (range as u32 as usize, (range >> 32) as usize);
        let (Some(ja), Some(db)) = (
            crate::rng::lemire32((w2 >> 32) as u32, ga.cap),
            crate::rng::lemire32(w2 as u32, nk as u32),
        ) else {
            // A slot must be redrawn (probability below n / 2^32): words 0 and 1 stand, the
            // slots (with their redraws) and the uniforms come one word at a time from word 2.
            self.rng.consume(2);
            let (ja, db) = self.rng.below_pair(ga.cap as usize, nk);
            let (u, gap) = (self.rng.f64(), self.rng.f64_open0());
            let pos = slot_position(ga.anchor, g, ja as u32);
            return Candidate::low_rank(ig, k, pos, ok + db, u, gap);
        };
        let (pos, b) = (slot_position(ga.anchor, g, ja), ok + db as usize);
        self.rng.consume(5);
        let u = crate::rng::unit_f64(w3);
        let gap = crate::rng::unit_f64_open0(w4);
        Candidate::low_rank(ig, k, pos, b, u, gap)
    }

    /// Recompute the hot-loop view of species s's groups.
    pub(super) fn sync_groups(&mut self, s: usize) {
        let gr = self.st.groups[s];
        let mut start = self.off[s];
        for g in 0..GROUPS {
            self.gtab[GROUPS * s + g] = GroupInfo {
                start: start as u32,
                n: gr.n[g] as u32,
                cap: gr.cap[g] as u32,
                anchor: group_anchor(self.off[s], self.off[s + 1], g),
                bound: gr.bound(g, self.st.vmax[s]),
            };
            start += gr.n[g] as usize;
        }
    }

    /// A candidate resolved against the current groups: the position of a (None for a slot
    /// past its group's size) and u (b_a + b_b).
    #[inline(always)]
    fn resolve(&self, c: &Candidate) -> (Option<usize>, f64) {
        let i = (c.i & SPECIES_MASK) as usize;
        let g = (c.i >> GROUP_SHIFT) as usize;
        let k = c.k as usize;
        // SAFETY: gtab has GROUPS entries per species; i and k are species.
        let ga = unsafe { *self.gtab.get_unchecked(GROUPS * i + g) };
        let gk = unsafe { self.gtab.get_unchecked(GROUPS * k..GROUPS * k + GROUPS) };
        let b = c.b;
        let gb = gk[1..].iter().filter(|x| b >= x.start).count();
        let ub = c.u * (ga.bound + unsafe { gk.get_unchecked(gb) }.bound);
        // The slot is valid while the position it names is in its group.
        let pos = c.a;
        (
            (pos.wrapping_sub(ga.start) < ga.n).then_some(pos as usize),
            ub,
        )
    }

    /// Fill the candidate queue to [`AHEAD`] candidates. Their velocity lines are prefetched
    /// during the batch before theirs (`prefetch_candidate`); after a void, the first batch's
    /// here.
    #[inline(always)]
    fn fill(&mut self) {
        let fresh = self.batch.is_empty();
        while self.batch.len() < AHEAD {
            let c = self.draw_candidate();
            self.batch.push(c);
        }
        if fresh {
            // The batch's first LEAD candidates were not prefetched by the one before (the
            // rest are, in its loop).
            for j in 0..LEAD {
                self.prefetch_candidate(j);
            }
        }
    }

    /// Prefetch the velocity lines of queued candidate j's particles (the position of a
    /// slot past its group's size, a void trial, may lie outside the particles: clamped).
    #[inline(always)]
    fn prefetch_candidate(&self, j: usize) {
        let c = self.batch.get(j);
        let last = self.st.vel.len().wrapping_sub(1);
        prefetch_record(&self.st.vel, (c.a as usize).min(last));
        prefetch_record(&self.st.vel, c.b as usize);
    }

    /// Apply the accepted collision of particles a (species i) and b (species k), velocities
    /// va and vb, relative velocity g (|g|^2 = g2), at time t (NaN for lazy collision times,
    /// where the time is not needed); then move the two particles
    /// to the groups their new speeds belong to. Returns whether the proposal tables changed
    /// (a speed bound raised, a group past its capacity, a refresh done): the candidates drawn
    /// ahead came from the old tables and are void (the decision depends only on the past).
    ///
    /// Impact directions come from their own stream (`geom`), one draw per collision in
    /// collision order.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn collide_now(
        &mut self,
        (a, i): (usize, usize),
        (b, k): (usize, usize),
        va: [f64; 3],
        vb: [f64; 3],
        g: [f64; 3],
        g2: f64,
        t: f64,
    ) -> bool {
        debug_assert!(a < self.st.vel.len() && b < self.st.vel.len());
        debug_assert!(i < self.sys.species.len() && k < self.sys.species.len());
        let (w, gne) = impact_impulse(g, g2, &mut self.geom);
        // SAFETY (this function): a and b are particle positions, i and k species.
        let (ma, mb) = unsafe {
            (
                self.sys.species.get_unchecked(i).mass,
                self.sys.species.get_unchecked(k).mass,
            )
        };
        let (mut na, mut nb) = (va, vb);
        let eps = self.eps.eps(i, k, gne);
        collide_impulse(&mut na, &mut nb, ma, mb, eps, w);
        if !self.st.disp.is_empty() {
            // The displacements are updated a little later (their lines are fetched
            // meanwhile), in collision order, before anything reads or moves them.
            prefetch(self.st.disp.as_ptr().wrapping_add(a));
            prefetch(self.st.disp.as_ptr().wrapping_add(b));
            self.disp_pending.push((a, va, t), (b, vb, t));
            if self.disp_pending.full() {
                self.flush_displacements();
            }
            self.st.t = t;
        }
        unsafe {
            *self.st.vel.get_unchecked_mut(a) = na;
            *self.st.vel.get_unchecked_mut(b) = nb;
            *self.st.species_collisions.get_unchecked_mut(i) += 1;
            *self.st.species_collisions.get_unchecked_mut(k) += 1;
        }
        self.st.collisions += 1;
        // Raise bounds that a new speed exceeds.
        let mut changed = false;
        let (s2a, s2b) = (speed2(&na), speed2(&nb));
        for (s, s2) in [(i, s2a), (k, s2b)] {
            let vmax = unsafe { self.st.vmax.get_unchecked_mut(s) };
            if s2 > *vmax * *vmax {
                *vmax = s2.sqrt() * RAISE_SLACK;
                changed = true;
            }
        }
        if changed {
            self.st.bound_raises += 1;
            self.sync_groups(i);
            self.sync_groups(k);
        }
        let mut b = b;
        let mut overflow = self.relocate(a, i, s2a, &mut b);
        let mut none = usize::MAX;
        overflow |= self.relocate(b, k, s2b, &mut none);
        if changed || overflow {
            self.rebuild_rates();
        }
        if self.refresh_due() {
            self.refresh_bounds();
            return true;
        }
        changed || overflow
    }

    /// Apply the pending displacement updates, in collision order: each particle moved with
    /// its velocity before the collision since its last update.
    pub(super) fn flush_displacements(&mut self) {
        for &(j, v, t) in self.disp_pending.take() {
            drift(&mut self.st.disp[j], v, t);
        }
    }

    /// Exchange the particles at positions x and y (velocity, displacement, id).
    fn swap_particles(&mut self, x: usize, y: usize) {
        if x == y {
            return;
        }
        if !self.disp_pending.is_empty() {
            self.flush_displacements();
        }
        self.st.vel.swap(x, y);
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
        let plan = self.sys.observe.tamsd.as_ref()?;
        let id = id as usize;
        let s = self.off.partition_point(|&o| o <= id) - 1;
        let t = id - self.off[s];
        (t < plan.tracers[s]).then(|| plan.tracers[..s].iter().sum::<usize>() + t)
    }

    /// Positions of the tracers, in tracer order (from `st.ids`).
    pub(super) fn tracer_positions(&self) -> Vec<u32> {
        let Some(plan) = &self.sys.observe.tamsd else {
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

    /// Move the particle at position x (species s, squared speed `s2`) into the group its
    /// speed belongs to (one swap with the particle at each group boundary crossed); `other`,
    /// a position, follows the particle it holds. Returns whether a group outgrew its proposal
    /// capacity (the capacities are then reset; the caller rebuilds the rates).
    #[inline(always)]
    fn relocate(&mut self, x: usize, s: usize, s2: f64, other: &mut usize) -> bool {
        debug_assert_eq!(s2.to_bits(), speed2(&self.st.vel[x]).to_bits());
        // From the hot-loop view of the groups (`sync_groups` keeps it in step with
        // `st.groups`): the bounds below the top group are the species' thresholds (negative:
        // one group), the groups' starts their first positions.
        debug_assert!(s < self.sys.species.len());
        // SAFETY: gtab has GROUPS entries per species.
        let gi = unsafe { self.gtab.get_unchecked(GROUPS * s..GROUPS * s + GROUPS) };
        // Split as `SpeciesGroups::split` decides (the first threshold not negative).
        let split = gi[0].bound >= 0.0;
        debug_assert_eq!(split, self.st.groups[s].split());
        if !split {
            return false;
        }
        let want = gi[..GROUPS - 1]
            .iter()
            .filter(|x| s2 > x.bound * x.bound)
            .count();
        debug_assert_eq!(want, self.st.groups[s].group_of(s2));
        // The current group.
        let g = gi[1..].iter().filter(|h| x >= h.start as usize).count();
        if g == want {
            return false;
        }
        self.relocate_slow(x, s, other, g, want)
    }

    #[inline(never)]
    fn relocate_slow(
        &mut self,
        mut x: usize,
        s: usize,
        other: &mut usize,
        mut g: usize,
        want: usize,
    ) -> bool {
        let mut gr = self.st.groups[s];
        // The first position of each group.
        let mut first = [0usize; GROUPS + 1];
        first[0] = self.off[s];
        for h in 0..GROUPS {
            first[h + 1] = first[h] + gr.n[h] as usize;
        }
        while g != want {
            // Swap with the particle at the boundary towards `want`; the boundary moves
            // past x, which changes group.
            let y = if want > g {
                gr.n[g] -= 1;
                gr.n[g + 1] += 1;
                first[g + 1] -= 1;
                first[g + 1]
            } else {
                gr.n[g] -= 1;
                gr.n[g - 1] += 1;
                first[g] += 1;
                first[g] - 1
            };
            self.swap_particles(x, y);
            if *other == y {
                *other = x;
            }
            x = y;
            g = if want > g { g + 1 } else { g - 1 };
        }
        let mut overflow = false;
        if gr.n.iter().zip(&gr.cap).any(|(n, c)| n > c) {
            gr.cap = gr.n.map(capacity);
            overflow = true;
        }
        self.st.groups[s] = gr;
        self.sync_groups(s);
        overflow
    }

    /// Split every species (with at least GROUP_MIN particles) into its speed groups at
    /// GROUP_FACTORS times its rms speed (after `refresh_bounds` set vmax; `v2sums`: each
    /// species' sum of squared speeds), and set the capacities.
    pub(super) fn regroup(&mut self, v2sums: &[f64]) {
        for s in 0..self.sys.species.len() {
            let count = self.sys.species[s].count;
            let (lo, hi) = (self.off[s], self.off[s + 1]);
            if count < GROUP_MIN {
                self.st.groups[s] = SpeciesGroups::single(count);
                self.sync_groups(s);
                continue;
            }
            debug_assert_eq!(
                v2sums[s].to_bits(),
                self.st.vel[lo..hi]
                    .iter()
                    .map(speed2)
                    .sum::<f64>()
                    .to_bits()
            );
            let rms = (v2sums[s] / count as f64).sqrt();
            let thr = GROUP_FACTORS.map(|f| (f * rms).min(self.st.vmax[s]));
            // Partition group by group: particles of group g first among those left
            // (Hoare, deterministic).
            let mut n = [0u64; GROUPS];
            let mut start = lo;
            for (g, &t) in thr.iter().enumerate() {
                let t2 = t * t;
                let (mut x, mut y) = (start, hi);
                loop {
                    while x < y && speed2(&self.st.vel[x]) <= t2 {
                        x += 1;
                    }
                    while x < y && speed2(&self.st.vel[y - 1]) > t2 {
                        y -= 1;
                    }
                    if x + 1 >= y {
                        break;
                    }
                    self.swap_particles(x, y - 1);
                    x += 1;
                    y -= 1;
                }
                n[g] = (x - start) as u64;
                start = x;
            }
            n[GROUPS - 1] = (hi - start) as u64;
            self.st.groups[s] = SpeciesGroups {
                n,
                cap: n.map(capacity),
                thr,
            };
            self.sync_groups(s);
        }
    }

    /// One batch: fill the queue, then try its candidates `start..BATCH` in order (a batch
    /// starts at 0; a continued run finishes the batch of its stop), each resolved against
    /// the current groups. An accepted collision is applied at once (its particles change
    /// groups at once), after the outputs before its time; when it changes the proposal
    /// tables the queue is void and the batch ends. Adds the trials (void ones excluded) to
    /// `trials`.
    #[inline(always)]
    fn low_rank_batch(&mut self, start: usize, trials: &mut u64) -> Result<BatchEnd, PhysicsError> {
        self.fill();
        let lazy = self.lazy_time();
        let mut tried = BATCH;
        let mut end = BatchEnd::More;
        for j in start..BATCH {
            // The queue holds AHEAD candidates until this loop ends (a void clears it and
            // leaves the loop). The candidate LEAD places on is prefetched, one per trial, so
            // that the misses are spread over the batch (a burst of them stalls on the miss
            // buffers).
            self.prefetch_candidate(j + LEAD);
            let c = self.batch.get(j);
            // Resolved: a's position (None for a slot past its group's size, a void trial).
            let (apos, ub) = self.resolve(&c);
            self.gap_factor(c.gap);
            let Some(a) = apos else {
                continue;
            };
            let b = c.b as usize;
            debug_assert!(a < self.st.vel.len() && b < self.st.vel.len());
            // SAFETY: a resolved candidate's a and b are particle positions.
            let (va, vb) =
                unsafe { (*self.st.vel.get_unchecked(a), *self.st.vel.get_unchecked(b)) };
            let (g, g2) = relative_speed2(&va, &vb);
            if ub * ub >= g2 {
                continue;
            }
            match self.accepted(j, &c, (a, b), (va, vb), (g, g2), lazy, None)? {
                Accepted::Go => {}
                Accepted::Done => {
                    tried = j + 1;
                    end = BatchEnd::Done;
                    break;
                }
                Accepted::Void => {
                    tried = j + 1;
                    end = BatchEnd::Void;
                    break;
                }
            }
        }
        match end {
            BatchEnd::Void => {
                self.void_queue();
                end = BatchEnd::More;
            }
            BatchEnd::More => self.batch.advance(tried),
            BatchEnd::Done => {}
        }
        *trials += (tried - start) as u64;
        Ok(end)
    }

    /// An accepted collision (candidate `j` of the batch: a and b, their velocities, g and
    /// |g|^2) at the time of its trial (`fixed`: a time already computed, for the stop of a
    /// continued run). Outputs before its time see the old state; with lazy times the time
    /// is computed only when it may be at or after the next output (it then becomes the new
    /// `st.t`).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn accepted(
        &mut self,
        j: usize,
        c: &Candidate,
        (a, b): (usize, usize),
        (va, vb): ([f64; 3], [f64; 3]),
        (g, g2): ([f64; 3], f64),
        lazy: bool,
        fixed: Option<f64>,
    ) -> Result<Accepted, PhysicsError> {
        let t = if fixed.is_some() || !lazy || self.st.gap_prod <= self.lazy_thr {
            let t = match fixed {
                Some(t) => t,
                None => self.gap_time(),
            };
            self.st.t = t;
            if self.next_event <= t && self.outputs_before(t)? {
                self.stop = Some(super::Stop::LowRank { slot: j as u32, t });
                return Ok(Accepted::Done);
            }
            self.update_lazy_threshold();
            t
        } else {
            f64::NAN
        };
        let (i, k) = ((c.i & SPECIES_MASK) as usize, c.k as usize);
        let rate = self.rate;
        if self.collide_now((a, i), (b, k), va, vb, g, g2, t) {
            if lazy {
                // The tables changed: fix the time of this collision (at the old rate).
                self.st.t += self.gap_elapsed(rate);
            }
            return Ok(Accepted::Void);
        }
        Ok(Accepted::Go)
    }

    /// The candidates drawn ahead came from tables that changed: drop them.
    fn void_queue(&mut self) {
        self.batch.clear();
        self.st.gap_prod = 1.0;
        self.st.gap_log = 0.0;
        self.update_lazy_threshold();
    }

    /// Whether queued candidate `slot` resolves to a particle.
    pub(super) fn resolvable(&self, slot: usize) -> bool {
        slot < self.batch.len() && self.resolve(&self.batch.get(slot)).0.is_some()
    }

    /// Continue a run that stopped at candidate `slot` of its batch, accepted at time `t`:
    /// apply it as the longer run does, then try the rest of the batch. True if the run is
    /// done again.
    pub(super) fn resume_low_rank(&mut self, slot: usize, t: f64) -> Result<bool, PhysicsError> {
        let c = self.batch.get(slot);
        let a = self.resolve(&c).0.expect("checked by continue_from");
        let b = c.b as usize;
        let (va, vb) = (self.st.vel[a], self.st.vel[b]);
        let (g, g2) = relative_speed2(&va, &vb);
        let lazy = self.lazy_time();
        let mut trials = 0;
        let end = match self.accepted(slot, &c, (a, b), (va, vb), (g, g2), lazy, Some(t))? {
            Accepted::Go => self.low_rank_batch(slot + 1, &mut trials)?,
            Accepted::Done => BatchEnd::Done,
            Accepted::Void => {
                self.void_queue();
                BatchEnd::More
            }
        };
        self.st.trials += trials;
        self.flush_displacements();
        Ok(matches!(end, BatchEnd::Done))
    }

    /// Up to about `max_trials` trials (whole batches); true when the run reached t_end. The
    /// loop runs compiled for x86-64-v3 where the CPU has it ([`x86_64_v3`]), else for the
    /// baseline: the same operations (no fused multiply-add), so the same bits.
    pub(super) fn advance_low_rank(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        #[cfg(target_arch = "x86_64")]
        if x86_64_v3() {
            // SAFETY: the CPU has the features the copy is compiled for.
            return unsafe { self.advance_low_rank_v3(max_trials) };
        }
        self.advance_low_rank_with(max_trials)
    }

    /// [`advance_low_rank`](Self::advance_low_rank) compiled for x86-64-v3 (AVX2, BMI1/2,
    /// LZCNT, POPCNT: three-operand vector instructions, flag-free shifts; no FMA).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn advance_low_rank_v3(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        self.advance_low_rank_with(max_trials)
    }

    /// The loop itself, compiled for the features of its caller.
    #[inline(always)]
    pub(super) fn advance_low_rank_with(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        let mut trials = 0u64;
        let result = loop {
            if self.rate <= 0.0 {
                break self.idle_to_end();
            }
            if trials >= max_trials {
                break Ok(false);
            }
            match self.low_rank_batch(0, &mut trials) {
                Ok(BatchEnd::More | BatchEnd::Void) => {}
                Ok(BatchEnd::Done) => break Ok(true),
                Err(e) => break Err(e),
            }
        };
        self.st.trials += trials;
        self.flush_displacements();
        result
    }
}

/// Whether the CPU runs x86-64-v3 code (the features of
/// [`DsmcSim::advance_low_rank_v3`]).
#[cfg(target_arch = "x86_64")]
fn x86_64_v3() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("popcnt")
}

/// The relative velocity g = va - vb and |g|^2.
#[inline(always)]
fn relative_speed2(va: &[f64; 3], vb: &[f64; 3]) -> ([f64; 3], f64) {
    let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
    (g, g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
}

/// |v|^2, summed as (x^2 + y^2) + z^2.
#[inline(always)]
pub(super) fn speed2(v: &[f64; 3]) -> f64 {
    v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
}

/// Prefetch the cache line(s) of a 24-byte velocity record (a quarter of them straddle two)
/// into L1: it is read LEAD trials later (L1 rather than L2: 1.5-3 % less CPU time for Table I on
/// both an Intel and an AMD machine; docs/performance.md).
#[inline(always)]
fn prefetch_record(vel: &[[f64; 3]], j: usize) {
    let p = vel.as_ptr().wrapping_add(j) as *const u8;
    prefetch_l1(p);
    prefetch_l1(p.wrapping_add(23));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dsmc::system::{power_law_species, RestitutionModel, TamsdPlan};

    /// The queue holds positions, checkpoints slots: the two convert into each other, and a
    /// position is in its group exactly when the slot is below the group's size, whatever
    /// the sizes (the validity the trial decides on).
    #[test]
    fn slots_and_positions_convert_and_agree_on_validity() {
        let off = [0usize, 5, 105, 1105];
        let mut checked = 0;
        for i in 0..3 {
            let count = (off[i + 1] - off[i]) as u64;
            for n0 in [0, 1, count / 3, count] {
                let n = [n0, count - n0];
                let start = [off[i] as u32, (off[i] as u64 + n0) as u32];
                for g in 0..GROUPS {
                    let ig = i as u32 | (g as u32) << GROUP_SHIFT;
                    for ja in (0..count as u32 + 20).chain([u32::MAX - 1, u32::MAX]) {
                        let c = Candidate::low_rank(ig, 0, ja, 0, 0.5, 0.5);
                        let q = candidate_position(&c, &off);
                        assert_eq!(candidate_slot(&q, &off), c);
                        let valid = q.a.wrapping_sub(start[g]) < n[g] as u32;
                        assert_eq!(valid, (ja as u64) < n[g], "i {i} g {g} n {n:?} ja {ja}");
                        if valid {
                            // Group 0's slots count up from its start, group 1's down
                            // from its end.
                            let want = match g {
                                0 => start[0] + ja,
                                _ => start[1] + n[1] as u32 - 1 - ja,
                            };
                            assert_eq!(q.a, want);
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert!(checked > 2000);
    }

    /// The power law n1 = 0.1, N1 = 3000, theta = 2.5, eps = 0.3, t_end = 40, msd on, bounds
    /// refreshed every 0.3 N collisions; with `tamsd` also 50 tracers on a grid of 40 (lag 1).
    fn sim(tamsd: bool) -> DsmcSim {
        let species = power_law_species(3000, 2.5, 1.0).unwrap();
        let volume = 3000.0 / 0.1;
        let tamsd = tamsd.then(|| TamsdPlan {
            grid: 40,
            tracers: species.iter().map(|s| s.count.min(50) as usize).collect(),
            lag_steps: vec![1],
            lags: vec![1.0],
        });
        let sys = DsmcSystem {
            method: Method::LowRank,
            species,
            volume,
            restitution: RestitutionModel::Constant(0.3),
            t_end: 40.0,
            output_times: vec![0.0, 40.0],
            observe: crate::dsmc::Observed {
                msd: true,
                tamsd,
                ..Default::default()
            },
            refresh_every: 0.3,
            rate_scale: std::f64::consts::PI / (4.0 * volume),
        };
        DsmcSim::new(sys, 77)
    }

    /// A checkpoint whose queued candidate names a particle outside its species k (which
    /// would move particles across species ranges and index out of bounds), or whose gap
    /// accumulator or counters are impossible, is refused; the untouched one is accepted.
    #[test]
    fn restore_refuses_impossible_candidates_and_counters() {
        let mut s = sim(false);
        s.advance(5_000).unwrap();
        let sys = s.sys.clone();
        let bytes = s.state_bytes();
        let st: DsmcState = postcard::from_bytes(&bytes).unwrap();
        assert!(!st.pipeline.is_empty());
        let edit = |f: &dyn Fn(&mut DsmcState)| {
            let mut st = st.clone();
            f(&mut st);
            DsmcSim::from_state_bytes(sys.clone(), &postcard::to_stdvec(&st).unwrap())
        };
        assert!(edit(&|_| {}).is_ok());
        let off = s.off.clone();
        let outside = edit(&|st| {
            // The first particle of the next species, or the last of the previous one.
            let k = st.pipeline[0].k as usize;
            let m = off.len() - 1;
            st.pipeline[0].b = if k + 1 < m { off[k + 1] } else { off[k] - 1 } as u32;
        });
        assert!(
            outside.is_err(),
            "a candidate's b outside species k was accepted"
        );
        for bad in [f64::NAN, 0.0, 2.0] {
            assert!(edit(&|st| st.gap_prod = bad).is_err(), "gap_prod {bad}");
        }
        assert!(edit(&|st| st.collisions_at_refresh = st.collisions + 1).is_err());
        assert!(edit(&|st| st.rng.filled_at = u128::MAX - 8).is_err());
        assert!(edit(&|st| st.geom.filled_at = 1 << 64).is_err());
        assert!(edit(&|st| st.next_output = usize::MAX).is_err());
    }

    /// Displacement updates wait in `disp_pending` (flushed before outputs, swaps and the end
    /// of `advance`): a run advanced in chunks of 777 trials ends with bitwise the same
    /// displacements, velocities and rows as one advanced in a single call, and the
    /// displacements did move.
    #[test]
    fn pending_displacements_are_invisible() {
        let mut one = sim(false);
        while !one.advance(u64::MAX).unwrap() {}
        let mut chunked = sim(false);
        while !chunked.advance(777).unwrap() {
            assert!(chunked.disp_pending.is_empty());
        }
        let bits = |s: &DsmcSim| -> Vec<u64> {
            s.st.disp
                .iter()
                .flatten()
                .chain(s.st.vel.iter().flatten())
                .map(|x| x.to_bits())
                .collect()
        };
        assert_eq!(bits(&one), bits(&chunked));
        assert_eq!(one.st.rows, chunked.st.rows);
        assert!(one.st.disp.iter().any(|d| d[0] != 0.0 && d[3] > 0.0));
    }

    /// After every chunk of a run (batches end between chunks): the groups are consistent
    /// (sizes add up, capacities hold them), every particle's speed is within its group's
    /// bound, the particle ids are a permutation whose tracers are where `tracer_pos` says,
    /// and particles did change groups (so the moves were exercised).
    #[test]
    fn groups_hold_their_particles() {
        for tamsd in [false, true] {
            let mut s = sim(tamsd);
            let m = s.sys.species.len();
            assert!(s.st.groups.iter().filter(|g| g.split()).count() >= 3);
            let first = s.st.groups.clone();
            let mut changed = false;
            loop {
                let done = s.advance(5_000).unwrap();
                check_groups(&s.sys, &s.st).unwrap();
                for k in 0..m {
                    let gr = s.st.groups[k];
                    let mut start = s.off[k];
                    for g in 0..GROUPS {
                        let bound = gr.bound(g, s.st.vmax[k]);
                        for v in &s.st.vel[start..start + gr.n[g] as usize] {
                            assert!(
                                speed2(v).sqrt() <= bound,
                                "species {k} group {g}: speed {} above bound {bound}",
                                speed2(v).sqrt()
                            );
                        }
                        start += gr.n[g] as usize;
                    }
                    assert_eq!(start, s.off[k + 1]);
                }
                if tamsd {
                    for (q, &p) in s.tracer_pos.clone().iter().enumerate() {
                        assert_eq!(s.tracer_number(s.st.ids[p as usize]), Some(q));
                    }
                }
                changed |= s.st.groups != first;
                if done {
                    break;
                }
            }
            assert!(changed, "no particle changed group");
            assert!(s.st.collisions > 20_000, "{} collisions", s.st.collisions);
        }
    }
}
