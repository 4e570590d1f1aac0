//! DSMC of polydisperse granular gases in the homogeneous cooling state (spec `dsmc.md`).
//!
//! - [`system`]: species, volume and output schedule resolved from the manifest.
//! - [`collision`]: the binary inelastic collision (41) and the choice of the inter-centre
//!   vector.
//! - [`low_rank`]: the paper's low-rank pair selection (section III.A).
//! - [`bird`]: Bird's method (section III.B), the baseline.
//! - [`alias`]: O(1) discrete sampling used by the low-rank selection.
//!
//! Both methods simulate the same stochastic process (spec section 4): trials form a Poisson
//! process whose rate majorises the true collision rate; a trial is accepted with the ratio of
//! the true rate to the majorant. Particles of one species are stored contiguously.

pub mod alias;
pub mod bird;
pub mod collision;
pub mod low_rank;
pub mod predict;
pub mod row_values;
pub mod system;
pub mod vdist;
pub mod viscoelastic;

use serde::{Deserialize, Serialize};

use crate::physics::{PhysicsError, SimError};
use crate::rng::{Generator, RngPosition, RunRng, StreamVersion};
use alias::Alias;
pub use row_values::{RowValue, RowValueSet, RowValues};
pub use system::{DsmcSystem, Method, Observed, RestitutionModel, SpeciesInfo, VdistPlan};

/// One row of the `dsmc_species` table (without the run's ids).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SpeciesRow {
    pub t: f64,
    /// Species index k, from 1.
    pub species: u32,
    pub mass: f64,
    pub diameter: f64,
    pub count: u64,
    /// T_k = m_k <v^2>_k / 3.
    pub temperature: f64,
    /// <R_k^2(t)>, when displacements are recorded.
    pub msd: Option<f64>,
    /// The optional per-row values (a2 of `velocity_distribution`, ...; see [`row_values`]),
    /// None where not recorded. Not in the row's own layout: saved after the state (see
    /// [`DsmcSim::state_bytes`]), so a state without such observables is a dsmc/5 one.
    #[serde(skip)]
    pub values: RowValues,
    /// Collisions that species-k particles took part in up to t (a k-k collision counts twice).
    pub collisions: u64,
}

impl SpeciesRow {
    /// Per-row value `v` (None where it is not recorded).
    pub fn value(&self, v: RowValue) -> Option<f64> {
        self.values.get(v)
    }
}

/// One row of the `dsmc_tamsd` table (without the run's ids): the time-averaged MSD (26) of
/// species `species` at lag `lag`, averaged over the species' tracers.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct TamsdRow {
    /// Species index k, from 1.
    pub species: u32,
    /// The lag Delta (a multiple of the grid step t_end / grid).
    pub lag: f64,
    /// <delta_k^2(Delta)>: the mean over tracers and over grid points t_j <= t_total - Delta of
    /// |R(t_j + Delta) - R(t_j)|^2.
    pub tamsd: f64,
    /// The measurement time t of (26): t_end.
    pub t_total: f64,
}

/// One row of the `dsmc_speed_histogram` table (without the run's ids): bin `bin` of the
/// scaled speed c = |v| / sqrt(2 T_k / m_k) of species `species` at time `t`.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct HistRow {
    pub t: f64,
    /// Species index k, from 1.
    pub species: u32,
    /// Bin index, from 0; the bin is [c_lo, c_hi).
    pub bin: u32,
    pub c_lo: f64,
    pub c_hi: f64,
    pub count: u64,
    /// count / (N_k (c_hi - c_lo)): integrates to the fraction of particles below c_max.
    pub density: f64,
}

/// A pre-drawn trial candidate: species pair and particle indices (global).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq)]
pub struct Candidate {
    pub i: u32,
    pub k: u32,
    pub a: u32,
    pub b: u32,
    /// The trial's acceptance uniform, drawn with the pair (low-rank: multiplied by the
    /// pair's group bounds when the candidate is resolved, at its trial).
    pub u: f64,
    /// Low-rank: the trial's uniform in (0, 1] for the exponential gap before it.
    pub gap: f64,
}

/// How many trials ahead candidates are drawn, so their velocities can be prefetched: the
/// ring is refilled in batches of `PIPELINE_DEPTH / 2` whenever half of it is used.
pub const PIPELINE_DEPTH: usize = 32;
/// Layout version of [`DsmcState`] in checkpoints (5: the low-rank queue holds two batches
/// and collisions are applied when accepted, so a dsmc/4 pipeline would resume differently;
/// with the observable `velocity_distribution` the payload goes on after the state with a
/// [`VdistExtra`], which a state without it lacks, so dsmc/5 payloads still decode; then,
/// only where a run records per-row values other than a2, one
/// [`row_values::RowValuesExtra`], which no older build wrote).
pub const STATE_FORMAT: &str = "dsmc/5";
/// Layout version of a finished run's [`FinalState`] (it embeds a [`STATE_FORMAT`] state).
pub const FINAL_FORMAT: &str = "dsmc/5+final/1";

/// What the observable `velocity_distribution` adds to a checkpoint, after the [`DsmcState`]:
/// the a2 of every recorded row and the histograms recorded so far.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct VdistExtra {
    pub a2: Vec<Option<f64>>,
    pub hist: Vec<HistRow>,
}

/// Where a finished run stopped: the first collision accepted past its last output, whose
/// time ended the run. It is not applied: a longer run of the same trajectory applies it
/// first ([`DsmcSim::continue_from`]).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub enum Stop {
    /// Low-rank: the candidate at `slot` of the batch being tried, accepted at time `t`.
    LowRank { slot: u32, t: f64 },
    /// Bird: particles `a` and `b` with the impact direction `e` drawn for them, accepted at
    /// time `t`.
    Bird { a: u32, b: u32, e: [f64; 3], t: f64 },
}

impl Stop {
    pub fn t(&self) -> f64 {
        match *self {
            Stop::LowRank { t, .. } | Stop::Bird { t, .. } => t,
        }
    }
}

/// What a finished run keeps so that a longer run can continue it (layout [`FINAL_FORMAT`]).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct FinalState {
    /// The run's end and output times: a longer run continues it only if its output times
    /// begin with exactly these (so every decision the shorter run made is the longer one's).
    pub t_end: f64,
    pub output_times: Vec<f64>,
    /// None when the run ended without a collision pending (every particle at rest).
    pub stop: Option<Stop>,
    /// The state at the end ([`DsmcSim::state_bytes`], with every row recorded).
    pub state: Vec<u8>,
}

/// A raised speed bound gets this much head-room, so that it is not raised again at once.
pub const RAISE_SLACK: f64 = 1.05;

/// The complete dynamical state of a run (what a checkpoint holds).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct DsmcState {
    pub t: f64,
    /// (vx, vy, vz): 24 bytes, so that the Table I gas (1.2M particles) fits in a 32 MB L3.
    pub vel: Vec<[f64; 3]>,
    /// (Rx, Ry, Rz, t_last) per particle; empty unless MSD or TAMSD is recorded.
    pub disp: Vec<[f64; 4]>,
    /// Low-rank: per-species speed bounds.
    pub vmax: Vec<f64>,
    /// Low-rank: each species' slow and fast speed groups (see [`low_rank`]).
    pub groups: Vec<low_rank::SpeciesGroups>,
    /// Low-rank with TAMSD: the original index of the particle at each position (particles
    /// change places between the speed groups); empty otherwise.
    pub ids: Vec<u32>,
    /// Bird: bound on ((sigma_j + sigma_M)/2)^2 |v_j|.
    pub bird_bound: f64,
    pub rng: RngPosition,
    /// Low-rank: the stream of impact directions (see [`geom_seed`]).
    pub geom: RngPosition,
    pub trials: u64,
    pub collisions: u64,
    pub species_collisions: Vec<u64>,
    pub bound_raises: u64,
    pub next_output: usize,
    /// TAMSD: the next grid point j to record (grid + 1 once all are recorded).
    pub next_grid: u64,
    /// TAMSD: tracer displacements R(t_j) at the grid points recorded so far, grid-point major
    /// (for each j, the tracers of species 1, then of species 2, ...); empty unless TAMSD is
    /// recorded.
    pub tracks: Vec<[f64; 3]>,
    pub collisions_at_refresh: u64,
    pub pipeline: Vec<Candidate>,
    /// Product of the uniforms U of the trials since `t` (the last collision, or for lazy
    /// low-rank times the last time fixed): the time to the next collision is
    /// -ln(prod U) / rate, the sum of the trials' exponential gaps.
    pub gap_prod: f64,
    /// Logs of underflow-guarded parts of that product.
    pub gap_log: f64,
    pub rows: Vec<SpeciesRow>,
    /// Speed histograms recorded so far (observable `velocity_distribution`); empty otherwise.
    /// Saved in the [`VdistExtra`] after the state.
    #[serde(skip)]
    pub hist: Vec<HistRow>,
    pub last_energy: f64,
    pub done: bool,
}

/// A running DSMC simulation.
pub struct DsmcSim {
    pub sys: DsmcSystem,
    pub st: DsmcState,
    rng: RunRng,
    /// Low-rank: impact directions (a stream of its own, see [`geom_seed`]).
    geom: RunRng,
    /// Low-rank: alias over (term r, species i) with weights W_r u_i^(r).
    pair_i: Alias,
    /// Low-rank: static alias over species k for each term r.
    pair_k: [Alias; 3],
    /// Species offsets into the particle arrays (M + 1 entries).
    off: Vec<usize>,
    /// Total trial rate.
    rate: f64,
    /// The next time at which something is recorded: the earlier of the next output time and
    /// the next TAMSD grid time (infinity when none is left). Derived from `next_output` and
    /// `next_grid`.
    next_event: f64,
    /// Refresh the bounds after this many collisions.
    refresh_collisions: u64,
    /// Low-rank: the static tables of a candidate's draw (slots decoded, k tables end to
    /// end, particle ranges), so decoding needs no division.
    draw: low_rank::DrawTables,
    /// Low-rank with TAMSD: the position of each tracer (derived from `st.ids`).
    tracer_pos: Vec<u32>,
    /// Low-rank without displacements: see [`update_lazy_threshold`](Self::update_lazy_threshold).
    lazy_thr: f64,
    /// Low-rank with displacements: updates of the last collisions not yet written (empty
    /// between `advance` calls, before outputs and before particles move).
    disp_pending: low_rank::PendingDisplacements,
    /// Low-rank: the groups as the hot loop reads them (derived from `st.groups`).
    gtab: Vec<low_rank::GroupInfo>,
    /// Bird: candidates drawn ahead (saved in `st.pipeline` at checkpoints).
    ring: Ring,
    /// Low-rank: the candidates drawn and not yet tried, two batches (saved in `st.pipeline`).
    batch: low_rank::CandidateQueue,
    /// Evaluates eps for a colliding pair.
    eps: EpsModel,
    /// Bird: per particle, an f32 upper bound (rounded up with margin) on
    /// ((sigma_j + sigma_M)/2)^2 |v_j|: the sum of the pair's bounds majorises the accepted
    /// quantity, so most trials are rejected without touching the velocity lines. Derived
    /// from `vel`; empty for low-rank.
    speed: Vec<f32>,
    /// A finished run: where it stopped. A continued run: the stop to apply first.
    stop: Option<Stop>,
    /// Whether `stop` is known for a finished run (not for one restored from a checkpoint
    /// taken after its end: such a run keeps no final state).
    stop_known: bool,
}

/// A fixed ring of pre-drawn candidates.
#[derive(Clone, Debug, Default)]
pub struct Ring {
    buf: [Candidate; PIPELINE_DEPTH],
    head: usize,
    len: usize,
}

impl Ring {
    #[inline(always)]
    pub fn push(&mut self, c: Candidate) {
        self.buf[(self.head + self.len) % PIPELINE_DEPTH] = c;
        self.len += 1;
    }
    #[inline(always)]
    pub fn pop(&mut self) -> Candidate {
        let c = self.buf[self.head];
        self.head = (self.head + 1) % PIPELINE_DEPTH;
        self.len -= 1;
        c
    }
    /// The candidate `j` places behind the oldest (j < len).
    #[inline(always)]
    pub fn peek(&self, j: usize) -> &Candidate {
        &self.buf[(self.head + j) % PIPELINE_DEPTH]
    }
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn clear(&mut self) {
        self.len = 0;
    }
    pub fn to_vec(&self) -> Vec<Candidate> {
        (0..self.len)
            .map(|j| self.buf[(self.head + j) % PIPELINE_DEPTH])
            .collect()
    }
    pub fn from_slice(cs: &[Candidate]) -> Ring {
        let mut r = Ring::default();
        for c in cs.iter().take(PIPELINE_DEPTH) {
            r.push(*c);
        }
        r
    }
}

impl DsmcSim {
    /// A fresh run: Maxwell velocities, zero total momentum, each species at its initial
    /// temperature; the t = 0 state is recorded.
    pub fn new(sys: DsmcSystem, seed: u64) -> Self {
        Self::with_generator(sys, seed, Generator::ChaCha8)
    }

    /// A fresh run drawing as stream version `stream` does (ChaCha8 words before version 3,
    /// AES-128 in counter mode from it).
    pub fn with_stream(sys: DsmcSystem, seed: u64, stream: StreamVersion) -> Self {
        Self::with_generator(sys, seed, stream.dsmc_generator())
    }

    fn with_generator(sys: DsmcSystem, seed: u64, generator: Generator) -> Self {
        let mut rng = RunRng::with_generator(seed, generator);
        let vel = system::initial_velocities(&sys, &mut rng);
        let n = vel.len();
        let m = sys.species.len();
        let st = DsmcState {
            t: 0.0,
            vel,
            disp: if sys.displacements() {
                crate::memory::huge_vec(n, [0.0; 4])
            } else {
                Vec::new()
            },
            vmax: vec![0.0; m],
            groups: Vec::new(),
            ids: if sys.method == Method::LowRank && sys.observe.tamsd.is_some() {
                (0..n as u32).collect()
            } else {
                Vec::new()
            },
            bird_bound: 0.0,
            rng: rng.position(),
            geom: RunRng::with_generator(geom_seed(seed), generator).position(),
            trials: 0,
            collisions: 0,
            species_collisions: vec![0; m],
            bound_raises: 0,
            next_output: 0,
            next_grid: 0,
            tracks: match &sys.observe.tamsd {
                Some(plan) => Vec::with_capacity(plan.n_tracers() * (plan.grid as usize + 1)),
                None => Vec::new(),
            },
            collisions_at_refresh: 0,
            pipeline: Vec::new(),
            gap_prod: 1.0,
            gap_log: 0.0,
            rows: Vec::new(),
            hist: Vec::new(),
            last_energy: f64::INFINITY,
            done: false,
        };
        let mut sim = Self::assemble(sys, st, rng);
        sim.refresh_bounds();
        sim
    }

    fn assemble(sys: DsmcSystem, st: DsmcState, rng: RunRng) -> Self {
        let geom = RunRng::restore_with(&st.geom, rng.generator());
        let off = species_offsets(&sys);
        let pair_k = low_rank::static_tables(&sys);
        let (ring, batch) = match sys.method {
            Method::LowRank => (
                Ring::default(),
                low_rank::CandidateQueue::from_slice(
                    &st.pipeline
                        .iter()
                        .map(|c| low_rank::candidate_position(c, &off))
                        .collect::<Vec<_>>(),
                ),
            ),
            Method::Bird => (
                Ring::from_slice(&st.pipeline),
                low_rank::CandidateQueue::from_slice(&[]),
            ),
        };
        let mut speed = Vec::new();
        if sys.method == Method::Bird {
            speed = crate::memory::huge_vec(st.vel.len(), 0f32);
            let sig_max = sys.sigma_max();
            for (k, sp) in sys.species.iter().enumerate() {
                let range = off[k]..off[k + 1];
                for (w, v) in speed[range.clone()].iter_mut().zip(&st.vel[range]) {
                    *w = bird::bird_weight(v, sp.diameter, sig_max);
                }
            }
        }
        let refresh_collisions = (sys.refresh_every * sys.n_particles() as f64)
            .ceil()
            .max(1.0) as u64;
        let draw = low_rank::DrawTables::new(&pair_k, &off);
        let mut st = st;
        if sys.method == Method::LowRank && st.groups.is_empty() {
            st.groups = sys
                .species
                .iter()
                .map(|sp| low_rank::SpeciesGroups::single(sp.count))
                .collect();
        }
        let eps = EpsModel::new(&sys);
        let st_done = st.done;
        let mut sim = DsmcSim {
            eps,
            sys,
            st,
            rng,
            geom,
            pair_i: Alias::default(),
            pair_k,
            off,
            rate: 0.0,
            next_event: f64::INFINITY,
            refresh_collisions,
            draw,
            tracer_pos: Vec::new(),
            gtab: Vec::new(),
            lazy_thr: 0.0,
            disp_pending: Default::default(),
            ring,
            batch,
            speed,
            stop: None,
            stop_known: !st_done,
        };
        if sim.sys.method == Method::LowRank {
            sim.tracer_pos = sim.tracer_positions();
            sim.gtab =
                vec![low_rank::GroupInfo::default(); low_rank::GROUPS * sim.sys.species.len()];
            for s in 0..sim.sys.species.len() {
                sim.sync_groups(s);
            }
        }
        sim.rebuild_rates();
        sim.update_next_event();
        sim
    }

    /// Serialise the state (the run's checkpoint payload).
    pub fn state_bytes(&mut self) -> Vec<u8> {
        self.st.rng = self.rng.position();
        self.st.geom = self.geom.position();
        self.st.pipeline = match self.sys.method {
            Method::LowRank => (self.batch.to_vec().iter())
                .map(|c| low_rank::candidate_slot(c, &self.off))
                .collect(),
            Method::Bird => self.ring.to_vec(),
        };
        let mut bytes = postcard::to_stdvec(&self.st).expect("state serialises");
        if self.sys.observe.vdist.is_some() {
            let extra = VdistExtra {
                a2: self.st.rows.iter().map(|r| r.value(RowValue::A2)).collect(),
                hist: self.st.hist.clone(),
            };
            bytes.extend(postcard::to_stdvec(&extra).expect("a2 and histograms serialise"));
        }
        row_values::save(
            self.sys.observe.values,
            &self.st.rows,
            |r| &r.values,
            &mut bytes,
        );
        // The stream version follows everything else (postcard varint of its number) when the
        // words are not ChaCha8's; nothing for ChaCha8, so those bytes are those of granular
        // before stream versions.
        if self.rng.generator() != Generator::ChaCha8 {
            let v = StreamVersion::V3.number();
            bytes.extend(postcard::to_stdvec(&v).expect("u32 serialises"));
        }
        bytes
    }

    /// The generator of the run's words.
    pub fn generator(&self) -> Generator {
        self.rng.generator()
    }

    /// Rebuild a simulation from a checkpoint payload.
    pub fn from_state_bytes(sys: DsmcSystem, bytes: &[u8]) -> Result<Self, SimError> {
        let (mut st, mut rest): (DsmcState, &[u8]) = postcard::take_from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        if sys.observe.vdist.is_some() {
            let (extra, after): (VdistExtra, &[u8]) = postcard::take_from_bytes(rest).map_err(|e| {
                format!("checkpoint has no velocity distribution (observable velocity_distribution): {e}")
            })?;
            if extra.a2.len() != st.rows.len() {
                return Err("checkpoint's a2 values do not match its rows".into());
            }
            for (r, a) in st.rows.iter_mut().zip(extra.a2) {
                r.values.set(RowValue::A2, a);
            }
            st.hist = extra.hist;
            rest = after;
        }
        rest = row_values::restore(sys.observe.values, &mut st.rows, |r| &mut r.values, rest)?;
        // Nothing left: ChaCha8 words (every checkpoint before stream version 3).
        let generator = if rest.is_empty() {
            Generator::ChaCha8
        } else {
            let mismatch = || {
                SimError::from(
                    "checkpoint does not match the run's observables (velocity_distribution or \
                     per-row values), or its stream version does not decode",
                )
            };
            let (number, tail): (u32, &[u8]) =
                postcard::take_from_bytes(rest).map_err(|_| mismatch())?;
            if !tail.is_empty() {
                return Err(mismatch());
            }
            let v = StreamVersion::try_from(number).map_err(|e| format!("checkpoint: {e}"))?;
            if v.dsmc_generator() == Generator::ChaCha8 {
                return Err(format!(
                    "checkpoint names stream version {number}, whose runs write no version"
                )
                .into());
            }
            v.dsmc_generator()
        };
        if st.vel.len() != sys.n_particles()
            || st.vmax.len() != sys.species.len()
            || st.species_collisions.len() != sys.species.len()
        {
            return Err("checkpoint does not match the run's species".into());
        }
        let (n, m) = (st.vel.len(), sys.species.len());
        let off = species_offsets(&sys);
        let foreign = |c: &Candidate| match sys.method {
            // Low-rank: a is a slot of the proposed group (a slot past the group's size is
            // a void trial), the group is in the top bits of i, b a particle of species k.
            Method::LowRank => {
                let i = (c.i & low_rank::SPECIES_MASK) as usize;
                let g = (c.i >> low_rank::GROUP_SHIFT) as usize;
                let k = c.k as usize;
                g >= low_rank::GROUPS
                    || i >= m
                    || k >= m
                    || !(off[k]..off[k + 1]).contains(&(c.b as usize))
            }
            Method::Bird => {
                c.a as usize >= n || c.b as usize >= n || c.i as usize >= m || c.k as usize >= m
            }
        };
        // A stream position past 2^64 32-bit words cannot come from a run (and would overflow
        // the generators' block arithmetic).
        if st.rng.filled_at >> 64 != 0 || st.geom.filled_at >> 64 != 0 {
            return Err("checkpoint's random stream position is out of range".into());
        }
        let counters_ok = st.next_output <= sys.output_times.len()
            && st.collisions_at_refresh <= st.collisions
            && st.gap_prod > 0.0
            && st.gap_prod <= 1.0
            && st.gap_log <= 0.0
            && st.gap_log.is_finite()
            && st.t.is_finite();
        if !counters_ok {
            return Err("checkpoint's counters or clock are inconsistent".into());
        }
        if st.pipeline.len() > PIPELINE_DEPTH.max(low_rank::AHEAD)
            || st.pipeline.iter().any(foreign)
        {
            return Err("checkpoint's candidate pipeline does not match the run".into());
        }
        if let Err(e) = low_rank::check_groups(&sys, &st) {
            return Err(SimError::State(format!(
                "checkpoint's speed groups do not match the run: {e}"
            )));
        }
        if st.disp.len() != if sys.displacements() { st.vel.len() } else { 0 } {
            return Err("checkpoint does not match the run's observables (displacements)".into());
        }
        let tracks_ok = match &sys.observe.tamsd {
            Some(plan) => {
                st.next_grid <= plan.grid + 1
                    && st.tracks.len() as u64 == st.next_grid * plan.n_tracers() as u64
            }
            None => st.next_grid == 0 && st.tracks.is_empty(),
        };
        if !tracks_ok {
            return Err("checkpoint does not match the run's observables (tamsd)".into());
        }
        let vdist_ok = match &sys.observe.vdist {
            Some(plan) => st
                .hist
                .iter()
                .all(|h| h.bin < plan.bins && plan.times.contains(&h.t)),
            None => st.hist.is_empty(),
        };
        if !vdist_ok {
            return Err(
                "checkpoint does not match the run's observables (velocity_distribution)".into(),
            );
        }
        let rng = RunRng::restore_with(&st.rng, generator);
        st.vel = crate::memory::huge_copy(&st.vel);
        st.disp = crate::memory::huge_copy(&st.disp);
        if let Some(plan) = &sys.observe.tamsd {
            // The trajectories grow to their final size without reallocating.
            let total = plan.n_tracers() * (plan.grid as usize + 1);
            st.tracks.reserve_exact(total - st.tracks.len());
        }
        Ok(Self::assemble(sys, st, rng))
    }

    /// A finished run's [`FinalState`] (layout [`FINAL_FORMAT`]); None for a run that is not
    /// finished or whose stop is unknown.
    pub fn final_state(&mut self) -> Option<Vec<u8>> {
        self.final_state_parts().map(|p| p.concat())
    }

    /// [`final_state`](Self::final_state) in two parts, the encoding of everything before the
    /// state's bytes (their length included), then the state's bytes: the concatenation is
    /// the postcard encoding of the [`FinalState`] (test `final_state_parts_are_its_encoding`),
    /// written without copying the state into a second buffer.
    pub fn final_state_parts(&mut self) -> Option<[Vec<u8>; 2]> {
        if !self.st.done || !self.stop_known {
            return None;
        }
        let state = self.state_bytes();
        let head = FinalState {
            t_end: self.sys.t_end,
            output_times: self.sys.output_times.clone(),
            stop: self.stop,
            state: Vec::new(),
        };
        let mut head = postcard::to_stdvec(&head).expect("final state serialises");
        // The empty state's length (a one-byte varint 0, last) becomes the state's length
        // (postcard writes a sequence's length as the varint of a usize).
        debug_assert_eq!(head.last(), Some(&0));
        head.pop();
        head.extend(postcard::to_stdvec(&state.len()).expect("usize serialises"));
        Some([head, state])
    }

    /// The run `sys` continued from a finished run's [`FinalState`], bit for bit the run made
    /// straight to `sys.t_end`: the stopping collision is applied with the rest of its batch,
    /// then the run goes on (see [`continuable`]; the time-averaged MSD, recorded on a grid
    /// that spans [0, t_end], cannot be continued).
    pub fn continue_from(sys: DsmcSystem, bytes: &[u8]) -> Result<Self, SimError> {
        let f: FinalState =
            postcard::from_bytes(bytes).map_err(|e| format!("final state does not decode: {e}"))?;
        if sys.observe.tamsd.is_some() {
            return Err("the time-averaged MSD is recorded on a grid that spans [0, t_end]".into());
        }
        continuable(f.t_end, &f.output_times, sys.t_end, &sys.output_times)?;
        let mut sim = Self::from_state_bytes(sys, &f.state)?;
        if !sim.st.done || sim.st.next_output != f.output_times.len() {
            return Err("final state is not that of a finished run".into());
        }
        if let Some(stop) = f.stop {
            let n = sim.st.vel.len();
            let ok = stop.t().is_finite()
                && stop.t() >= f.t_end
                && match stop {
                    Stop::LowRank { slot, .. } => {
                        (slot as usize) < low_rank::BATCH
                            && sim.batch.len() == low_rank::AHEAD
                            && sim.resolvable(slot as usize)
                    }
                    Stop::Bird { a, b, e, .. } => {
                        a != b
                            && (a as usize) < n
                            && (b as usize) < n
                            && e.iter().all(|x| x.is_finite())
                    }
                };
            if !ok {
                return Err("final state's stopping collision does not match the run".into());
            }
            sim.st.t = stop.t();
        }
        sim.st.done = false;
        sim.stop_known = true;
        sim.update_next_event();
        // Apply the stop now, so that no checkpoint is taken with it pending.
        if let Some(stop) = f.stop {
            sim.apply_stop(stop)
                .map_err(|e| format!("continuing at t = {}: {}", e.t, e.reason))?;
        }
        Ok(sim)
    }

    /// Apply the collision that stopped a shorter run (outputs before it first), as the
    /// longer run applies it; true if the run is done again.
    fn apply_stop(&mut self, stop: Stop) -> Result<bool, PhysicsError> {
        let done = match stop {
            Stop::LowRank { slot, t } => self.resume_low_rank(slot as usize, t)?,
            Stop::Bird { a, b, e, t } => self.resume_bird(a as usize, b as usize, e, t)?,
        };
        Ok(done)
    }

    pub fn is_done(&self) -> bool {
        self.st.done
    }

    /// Fraction of the run done, on a log scale of time (collisions per particle grow ~ ln t).
    pub fn progress(&self) -> f64 {
        if self.st.done {
            return 1.0;
        }
        ((1.0 + self.time()).ln() / (1.0 + self.sys.t_end).ln()).clamp(0.0, 1.0)
    }

    /// Run at most `max_trials` trials; `Ok(true)` once t_end is reached.
    pub fn advance(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        if self.st.done {
            return Ok(true);
        }
        match self.sys.method {
            Method::LowRank => self.advance_low_rank(max_trials),
            Method::Bird => self.advance_bird(max_trials),
        }
    }

    /// The time-averaged MSD (26) of every species at every lag, from the tracer trajectories
    /// (empty unless TAMSD is recorded and the run is complete). On the grid t_j = j h
    /// (h = t_end / grid), the integral of (26) becomes the mean over j = 0..=grid - l of
    /// |R(t_{j+l}) - R(t_j)|^2 for the lag Delta = l h, averaged over the species' tracers;
    /// summed in a fixed order (deterministic).
    pub fn tamsd_rows(&self) -> Vec<TamsdRow> {
        let Some(plan) = &self.sys.observe.tamsd else {
            return Vec::new();
        };
        if self.st.next_grid != plan.grid + 1 {
            return Vec::new();
        }
        let nt = plan.n_tracers();
        let grid = plan.grid as usize;
        let tracks = &self.st.tracks;
        debug_assert_eq!(tracks.len(), nt * (grid + 1));
        let mut rows = Vec::with_capacity(plan.tracers.len() * plan.lag_steps.len());
        let mut start = 0;
        for (s, &m) in plan.tracers.iter().enumerate() {
            for (&l, &lag) in plan.lag_steps.iter().zip(&plan.lags) {
                let l = l as usize;
                let mut sum = 0.0;
                for j in 0..=grid - l {
                    let a = &tracks[j * nt + start..j * nt + start + m];
                    let b = &tracks[(j + l) * nt + start..(j + l) * nt + start + m];
                    for (x, y) in a.iter().zip(b) {
                        let (dx, dy, dz) = (y[0] - x[0], y[1] - x[1], y[2] - x[2]);
                        sum += dx * dx + dy * dy + dz * dz;
                    }
                }
                rows.push(TamsdRow {
                    species: s as u32 + 1,
                    lag,
                    tamsd: sum / (m as f64 * (grid - l + 1) as f64),
                    t_total: self.sys.t_end,
                });
            }
            start += m;
        }
        rows
    }

    /// Take the recorded speed histograms (observable `velocity_distribution`).
    pub fn take_hist(&mut self) -> Vec<HistRow> {
        std::mem::take(&mut self.st.hist)
    }

    /// Take the recorded rows (the run's output so far).
    pub fn take_rows(&mut self) -> Vec<SpeciesRow> {
        std::mem::take(&mut self.st.rows)
    }

    /// Total trial rate for the current bounds.
    fn rebuild_rates(&mut self) {
        match self.sys.method {
            Method::LowRank => {
                let w = low_rank::dynamic_weights(
                    &self.sys,
                    &self.st.vmax,
                    &self.st.groups,
                    &self.pair_k,
                );
                self.pair_i.rebuild(&w);
                self.rate = self.sys.rate_scale * self.pair_i.total();
                self.update_lazy_threshold();
            }
            Method::Bird => {
                let n = self.sys.n_particles() as f64;
                self.rate =
                    n * n * 2.0 * self.st.bird_bound * std::f64::consts::PI / self.sys.volume;
            }
        }
    }

    /// Recompute exact speed bounds (they shrink as the gas cools) and the rates.
    fn refresh_bounds(&mut self) {
        let sig_max = self.sys.sigma_max();
        let mut bound: f64 = 0.0;
        // Each species' sum of squared speeds too, for the low-rank groups (in the same pass
        // over the velocities; summed in order from -0.0, as `Iterator::sum` does).
        let mut v2sums = Vec::with_capacity(self.sys.species.len());
        for (s, sp) in self.sys.species.iter().enumerate() {
            let (v2max, v2sum) = max_and_sum_speed2(&self.st.vel[self.off[s]..self.off[s + 1]]);
            v2sums.push(v2sum);
            let vmax = v2max.sqrt();
            self.st.vmax[s] = vmax;
            let c = 0.25 * (sp.diameter + sig_max) * (sp.diameter + sig_max);
            bound = bound.max(c * vmax);
        }
        self.st.bird_bound = bound;
        self.st.collisions_at_refresh = self.st.collisions;
        if self.sys.method == Method::LowRank {
            // Candidates drawn from the old tables are void.
            self.batch.clear();
            if !self.gtab.is_empty() {
                self.regroup(&v2sums);
            }
        }
        self.rebuild_rates();
    }

    #[inline(always)]
    fn refresh_due(&self) -> bool {
        self.st.collisions - self.st.collisions_at_refresh >= self.refresh_collisions
    }

    /// One more trial's uniform in the product that gives the time to the next collision.
    #[inline(always)]
    fn gap_trial(&mut self) {
        let u = self.rng.f64_open0();
        self.gap_factor(u);
    }

    /// Multiply a trial's gap uniform `u` into the product (its underflow-guarded part moved
    /// to `gap_log`, which moves the lazy-time threshold).
    #[inline(always)]
    fn gap_factor(&mut self, u: f64) {
        self.st.gap_prod *= u;
        if self.st.gap_prod < 1e-250 {
            self.st.gap_log += self.st.gap_prod.ln();
            self.st.gap_prod = 1.0;
            self.update_lazy_threshold();
        }
    }

    /// The sum of the exponential gaps of the trials in the product, at trial rate `rate`:
    /// -ln(prod U) / rate.
    #[inline(always)]
    fn gap_elapsed(&self, rate: f64) -> f64 {
        -(self.st.gap_log + self.st.gap_prod.ln()) / rate
    }

    /// Time of the trial just accepted: the trials since the last collision had i.i.d.
    /// exponential gaps of rate `rate`, and their sum is -ln(prod U) / rate. Resets the product.
    #[inline(always)]
    fn gap_time(&mut self) -> f64 {
        self.gap_time_from(self.st.t)
    }

    /// [`gap_time`](Self::gap_time) after a collision at `t_last`.
    #[inline(always)]
    fn gap_time_from(&mut self, t_last: f64) -> f64 {
        let dt = self.gap_elapsed(self.rate);
        self.st.gap_prod = 1.0;
        self.st.gap_log = 0.0;
        t_last + dt
    }

    /// With a zero trial rate (every particle at rest) nothing happens until t_end.
    fn idle_to_end(&mut self) -> Result<bool, PhysicsError> {
        self.outputs_before(f64::INFINITY)
    }

    /// Record the state at output time `t` (velocities are constant between collisions;
    /// displacements are extrapolated without modifying the stored ones).
    fn record(&mut self, t: f64) -> Result<(), PhysicsError> {
        let mut energy = 0.0;
        for (s, sp) in self.sys.species.iter().enumerate() {
            let range = self.off[s]..self.off[s + 1];
            let vel = &self.st.vel[range.clone()];
            let mut v2 = 0.0;
            for v in vel {
                v2 += v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            }
            let values = RowValues::compute(
                self.sys.observe.values,
                &row_values::SpeciesSample {
                    t,
                    mass: sp.mass,
                    diameter: sp.diameter,
                    count: sp.count,
                    vel,
                    v2,
                },
            );
            if let Some(plan) = &self.sys.observe.vdist {
                let scale = (2.0 * v2 / (3.0 * sp.count as f64)).sqrt();
                if plan.times.contains(&t) && scale > 0.0 && scale.is_finite() {
                    let counts = vdist::speed_histogram(vel, scale, plan.bins, plan.c_max);
                    let dc = plan.c_max / plan.bins as f64;
                    for (b, &count) in counts.iter().enumerate() {
                        self.st.hist.push(HistRow {
                            t,
                            species: s as u32 + 1,
                            bin: b as u32,
                            c_lo: b as f64 * dc,
                            c_hi: (b + 1) as f64 * dc,
                            count,
                            density: count as f64 / (sp.count as f64 * dc),
                        });
                    }
                }
            }
            let msd = if self.sys.observe.msd {
                let mut r2 = 0.0;
                for (v, d) in self.st.vel[range.clone()]
                    .iter()
                    .zip(&self.st.disp[range.clone()])
                {
                    let dt = t - d[3];
                    let (x, y, z) = (d[0] + v[0] * dt, d[1] + v[1] * dt, d[2] + v[2] * dt);
                    r2 += x * x + y * y + z * z;
                }
                Some(r2 / sp.count as f64)
            } else {
                None
            };
            energy += 0.5 * sp.mass * v2;
            let temperature = sp.mass * v2 / (3.0 * sp.count as f64);
            if !temperature.is_finite() || msd.is_some_and(|m| !m.is_finite()) {
                return Err(PhysicsError {
                    t,
                    reason: format!("non-finite temperature or MSD in species {}", s + 1),
                });
            }
            self.st.rows.push(SpeciesRow {
                t,
                species: s as u32 + 1,
                mass: sp.mass,
                diameter: sp.diameter,
                count: sp.count,
                temperature,
                msd,
                values,
                collisions: self.st.species_collisions[s],
            });
        }
        // Inelastic collisions never add energy; allow rounding only.
        if energy > self.st.last_energy * (1.0 + 1e-9) {
            return Err(PhysicsError {
                t,
                reason: format!(
                    "kinetic energy increased from {} to {energy}",
                    self.st.last_energy
                ),
            });
        }
        self.st.last_energy = energy;
        Ok(())
    }

    /// The earlier of the next output time and the next TAMSD grid time.
    fn update_next_event(&mut self) {
        let output = self
            .sys
            .output_times
            .get(self.st.next_output)
            .copied()
            .unwrap_or(f64::INFINITY);
        let grid = match &self.sys.observe.tamsd {
            Some(plan) if self.st.next_grid <= plan.grid => {
                plan.time(self.sys.t_end, self.st.next_grid)
            }
            _ => f64::INFINITY,
        };
        self.next_event = output.min(grid);
        self.update_lazy_threshold();
    }

    /// Low-rank without displacements, where a collision's time is needed only to know
    /// whether an output comes first: collision times are not summed one by one (a logarithm
    /// each); the trials' uniforms multiply on since the last time fixed (`st.t`), and the
    /// next collision is at or after `next_event` when the product is at or below this
    /// threshold, exp(-(next_event - t) rate - gap_log). Derived from the state (so a
    /// resumed run decides the same); recomputed whenever t, the rate, `gap_log` or
    /// `next_event` change.
    pub(super) fn update_lazy_threshold(&mut self) {
        self.lazy_thr = if self.lazy_time() && self.next_event.is_finite() && self.rate > 0.0 {
            (-(self.next_event - self.st.t) * self.rate - self.st.gap_log).exp()
        } else {
            0.0
        };
    }

    /// Whether collision times are fixed only when needed (see
    /// [`update_lazy_threshold`](Self::update_lazy_threshold)).
    #[inline(always)]
    pub(super) fn lazy_time(&self) -> bool {
        self.sys.method == Method::LowRank && self.st.disp.is_empty()
    }

    /// Simulated time reached: `st.t`, plus, for lazy collision times, the time of the
    /// trials since (without changing the state).
    pub fn time(&self) -> f64 {
        if self.lazy_time() && self.rate > 0.0 && !self.st.done {
            self.st.t + self.gap_elapsed(self.rate)
        } else {
            self.st.t
        }
    }

    /// Append the tracers' displacements at grid time `t` (extrapolated like `record`, without
    /// modifying the stored ones).
    fn record_tracks(&mut self, t: f64) {
        let Some(plan) = &self.sys.observe.tamsd else {
            return;
        };
        if !self.st.ids.is_empty() {
            for &p in &self.tracer_pos {
                let (v, d) = (self.st.vel[p as usize], self.st.disp[p as usize]);
                let dt = t - d[3];
                self.st
                    .tracks
                    .push([d[0] + v[0] * dt, d[1] + v[1] * dt, d[2] + v[2] * dt]);
            }
            return;
        }
        for (s, &m) in plan.tracers.iter().enumerate() {
            let range = self.off[s]..self.off[s] + m;
            for (v, d) in self.st.vel[range.clone()].iter().zip(&self.st.disp[range]) {
                let dt = t - d[3];
                self.st
                    .tracks
                    .push([d[0] + v[0] * dt, d[1] + v[1] * dt, d[2] + v[2] * dt]);
            }
        }
    }

    /// Emit every output time and TAMSD grid time up to `t_next` (the time of the next
    /// collision: they see the state before it); mark the run done if `t_next` is past t_end.
    #[inline]
    fn outputs_before(&mut self, t_next: f64) -> Result<bool, PhysicsError> {
        if !self.disp_pending.is_empty() {
            self.flush_displacements();
        }
        if let Some((grid, t_end)) = self
            .sys
            .observe
            .tamsd
            .as_ref()
            .map(|p| (p.grid, self.sys.t_end))
        {
            while self.st.next_grid <= grid {
                let t = system::grid_time(t_end, grid, self.st.next_grid);
                if t > t_next {
                    break;
                }
                self.record_tracks(t);
                self.st.next_grid += 1;
            }
        }
        while self.st.next_output < self.sys.output_times.len()
            && self.sys.output_times[self.st.next_output] <= t_next
        {
            let t = self.sys.output_times[self.st.next_output];
            self.record(t)?;
            self.st.next_output += 1;
        }
        self.update_next_event();
        if t_next > self.sys.t_end || self.st.next_output == self.sys.output_times.len() {
            self.st.t = self.sys.t_end;
            self.st.done = true;
            return Ok(true);
        }
        Ok(false)
    }

    /// Total momentum sum m v (for conservation checks).
    pub fn momentum(&self) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (s, sp) in self.sys.species.iter().enumerate() {
            for v in &self.st.vel[self.off[s]..self.off[s + 1]] {
                for d in 0..3 {
                    p[d] += sp.mass * v[d];
                }
            }
        }
        p
    }

    /// Sum of m v^2 over all particles.
    pub fn sum_mv2(&self) -> f64 {
        let mut e = 0.0;
        for (s, sp) in self.sys.species.iter().enumerate() {
            let mut v2 = 0.0;
            for v in &self.st.vel[self.off[s]..self.off[s + 1]] {
                v2 += v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            }
            e += sp.mass * v2;
        }
        e
    }
}

/// Restitution as the hot loop evaluates it; nothing is tabulated for constant eps.
pub enum EpsModel {
    Constant(f64),
    Viscoelastic {
        table: viscoelastic::ViscoelasticTable,
        /// A kappa_ki^(2/5) for every species pair (row-major, M x M).
        a_pair: Vec<f64>,
        m: usize,
    },
}

impl EpsModel {
    pub fn new(sys: &DsmcSystem) -> Self {
        match sys.restitution {
            RestitutionModel::Constant(e) => EpsModel::Constant(e),
            RestitutionModel::Viscoelastic { a_kappa } => {
                let m = sys.species.len();
                let mut a_pair = vec![0.0; m * m];
                for (k, sk) in sys.species.iter().enumerate() {
                    for (i, si) in sys.species.iter().enumerate() {
                        a_pair[k * m + i] = viscoelastic::pair_a_kappa(
                            a_kappa,
                            sk.mass,
                            sk.diameter,
                            si.mass,
                            si.diameter,
                        );
                    }
                }
                EpsModel::Viscoelastic {
                    table: viscoelastic::ViscoelasticTable::new(),
                    a_pair,
                    m,
                }
            }
        }
    }

    /// eps for species k, i colliding with normal impact speed `g_n`.
    #[inline(always)]
    pub fn eps(&self, k: usize, i: usize, g_n: f64) -> f64 {
        match self {
            EpsModel::Constant(e) => *e,
            EpsModel::Viscoelastic { table, a_pair, m } => table.eps_pair(a_pair[k * m + i], g_n),
        }
    }
}

/// Whether a finished run with end `t_end` and output times `old` can be continued to a run
/// with end `new_end` and output times `new`: a later end, and output times that begin with
/// exactly `old` (the decisions of the shorter run, which depend on its next output time, are
/// then those of the longer one). Err says why not.
pub fn continuable(t_end: f64, old: &[f64], new_end: f64, new: &[f64]) -> Result<(), SimError> {
    if new_end <= t_end || new_end.is_nan() {
        return Err(SimError::State(format!(
            "t_end {new_end} is not past the run's end {t_end}"
        )));
    }
    let differs = |j: usize| new.get(j).map(|x| x.to_bits()) != Some(old[j].to_bits());
    if let Some(j) = (0..old.len()).find(|&j| differs(j)) {
        let n = new.get(j).copied().unwrap_or(f64::NAN);
        return Err(SimError::State(format!(
            "the new output times differ from the run's before its end t = {t_end} (the \
             run's output {j} is at t = {}, the new one at t = {n}); listing {t_end} in \
             `output_times.list` keeps the old end on the grid",
            old[j]
        )));
    }
    Ok(())
}

/// Offsets of the species' particle ranges (M + 1 entries, the last one N).
pub fn species_offsets(sys: &DsmcSystem) -> Vec<usize> {
    let mut off = Vec::with_capacity(sys.species.len() + 1);
    off.push(0);
    for s in &sys.species {
        off.push(off.last().unwrap() + s.count as usize);
    }
    off
}

/// Move a displacement record [x, y, z, t_last] on to time t with velocity v (constant since
/// t_last).
#[inline(always)]
pub fn drift(d: &mut [f64; 4], v: [f64; 3], t: f64) {
    let dt = t - d[3];
    d[0] += v[0] * dt;
    d[1] += v[1] * dt;
    d[2] += v[2] * dt;
    d[3] = t;
}

/// Seed of a run's impact-direction stream (low-rank): a fixed bijective mix of the run's
/// seed (the splitmix64 finaliser), so the stream derives from the run's identity like the
/// main one and is independent of it.
pub fn geom_seed(seed: u64) -> u64 {
    let mut z = seed ^ 0x6a09_e667_f3bc_c909;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The largest squared speed in `vel` (0 for none; a NaN is passed over, as by `f64::max`)
/// and the sum of the squared speeds, added in order from -0.0 (as by `Iterator::sum`). The
/// maximum runs in four independent lanes, so the sum's chain of additions is the loop's only
/// carried dependence (a single `f64::max` chain, with its NaN test, was twice as long: most
/// of `refresh_bounds`). Exactly the values of the one-lane loop: a maximum does not depend
/// on grouping, and a squared speed is never -0.0.
fn max_and_sum_speed2(vel: &[[f64; 3]]) -> (f64, f64) {
    let mut lanes = [0.0f64; 4];
    let mut sum = -0.0;
    let mut quads = vel.chunks_exact(4);
    for q in &mut quads {
        for (lane, v) in lanes.iter_mut().zip(q) {
            let v2 = low_rank::speed2(v);
            if v2 > *lane {
                *lane = v2;
            }
            sum += v2;
        }
    }
    for v in quads.remainder() {
        let v2 = low_rank::speed2(v);
        if v2 > lanes[0] {
            lanes[0] = v2;
        }
        sum += v2;
    }
    let max = lanes
        .into_iter()
        .fold(0.0, |a, x| if x > a { x } else { a });
    (max, sum)
}

/// An f32 upper bound on |v|: relative margin 1e-7 (far above f64 rounding), rounded up.
#[inline(always)]
pub fn speed_bound(v: &[f64; 3]) -> f32 {
    let s = low_rank::speed2(v).sqrt() * (1.0 + 1e-7);
    let f = s as f32;
    if (f as f64) < s {
        f.next_up()
    } else {
        f
    }
}

/// Prefetch the cache line at `p` into the first-level cache (for data used within a few
/// hundred nanoseconds: the low-rank trials' velocity records).
#[inline(always)]
fn prefetch_l1<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    prefetch_hint::<{ core::arch::x86_64::_MM_HINT_T0 }, T>(p);
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Prefetch the cache line at `p` into the second-level cache.
#[inline(always)]
fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    prefetch_hint::<{ core::arch::x86_64::_MM_HINT_T1 }, T>(p);
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch_hint<const HINT: i32, T>(p: *const T) {
    // SAFETY: a prefetch never faults, whatever the address.
    #[allow(unused_unsafe)]
    unsafe {
        core::arch::x86_64::_mm_prefetch::<HINT>(p as *const i8);
    }
}

#[cfg(test)]
mod tests;
