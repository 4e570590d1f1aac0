//! [`RfmSim`]: the Random Force Model simulation (spec 1), one dimension chosen once at
//! construction and dispatched to the const-generic core [`Core<D>`].
//!
//! State (everything a checkpoint holds, [`RfmState`]): positions, velocities, the reference
//! positions of the last neighbour-list build and the largest displacement since, the random
//! stream's position, and the step count. The neighbour list is rebuilt on restore from the
//! reference positions, which reproduces it exactly, so a restored run continues bit for bit.

use serde::{Deserialize, Serialize};

use super::blocks::HistRow;
use super::contact::ContactLaw;
#[cfg(test)]
use super::drift::drift_portable;
#[cfg(target_arch = "x86_64")]
use super::drift::drift_round;
use super::drift::{drift_1d, drift_block, drift_one_flat, largest};
use super::freepath::{FreePathAcc, FreePathConfig, FreePathMomentRow, FreePaths};
use super::integrate::PairPropagator;
use super::neighbours::{cell_grid, cell_index, wrap, NeighbourList};
use super::noise::{CounterBlocks, Kicks, KICK_BLOCK, SLOT_KICK_BLOCK};
use super::params::{InitialLayout, RfmConfig};
use super::team::{self, run_parts};
use crate::physics::SimError;
use crate::rng::stream::WordStream;
use crate::rng::{RngPosition, RunRng, StreamVersion};

/// Runs with fewer particles step on the calling thread alone (no rayon call at all).
pub const PARALLEL_MIN_PARTICLES: usize = 4096;
/// Pairs per work block of the 2D pair pass, at most. The list is cut into a multiple of the
/// pool's thread count of blocks of equal length (to one pair; see [`pair_blocks`]), so
/// that each thread gets as many pairs (cut into 4096-pair blocks, 9 blocks over 2 threads
/// gave one thread 25 % more pairs and the other a wait in every step). The cut changes no
/// result: the corrections are applied in pair order whatever the blocks.
const PAIR_BLOCK: usize = 4096;

/// The 2D pair pass's blocks of a list of `pairs` pairs on `threads` threads: the least
/// multiple of `threads` of blocks of at most [`PAIR_BLOCK`] pairs, block k the pairs
/// [k pairs / nb, (k + 1) pairs / nb). Returns nb.
fn pair_blocks(pairs: usize, threads: usize) -> usize {
    let t = threads.max(1);
    t * pairs.div_ceil(t * PAIR_BLOCK).max(1)
}

/// Pair block `k` of `nb` of a list of `pairs` pairs (see [`pair_blocks`]).
fn pair_block(pairs: usize, nb: usize, k: usize) -> std::ops::Range<usize> {
    k * pairs / nb..(k + 1) * pairs / nb
}
/// Whether a run's noise is addressed by storage slot, in work blocks of [`SLOT_KICK_BLOCK`]
/// (stream version 4, 2D runs of at least [`PARALLEL_MIN_PARTICLES`] particles: those that
/// are kept stored by cell); else by particle, in blocks of [`KICK_BLOCK`] (version 4's
/// smaller runs draw as version 3's).
fn slot_noise<const D: usize>(stream: StreamVersion, n: usize) -> bool {
    stream.rfm_slot_noise() && D > 1 && n >= PARALLEL_MIN_PARTICLES
}

/// Particles per work block of the drift pass when version-2 kicks gather their normals
/// from a buffer (particles stored by cell; the blocks need not be the kick blocks then):
/// smaller blocks share the particles out more evenly between the threads. Otherwise the
/// drift's blocks (and those of the contact corrections' application) are the kicks' work
/// blocks ([`KICK_BLOCK`], or [`SLOT_KICK_BLOCK`] for stream version 4), so that one pass
/// drifts a block and kicks it for the next step.
const SORTED_DRIFT_BLOCK: usize = KICK_BLOCK / 2;

/// One particle block of the corrections-and-drift pass (block `b` of
/// [`Core::drift_block_len`] particles): its positions, velocities and references (empty in
/// 1D), and what the pass found (the largest displacement squared; the kick's sum of z and
/// largest |v|^2).
struct DriftJob<'a, const D: usize> {
    b: usize,
    x: &'a mut [[f64; D]],
    v: &'a mut [[f64; D]],
    r: &'a [[f64; D]],
    /// Particles stored by cell: the block's particle numbers, and the slots of block `b`
    /// of the normals two steps on, with their sum (see [`Core::noise`]).
    ids: &'a [u32],
    ahead: Option<(&'a mut [f64], &'a mut [f64; D])>,
    m: f64,
    kick: ([f64; D], f64),
}

/// One step's version-2 normals for particles stored out of slot order (see
/// [`Core::noise`]): all slots in slot order and each kick block's sum, for step `step`
/// (None: none yet).
struct StepNoise<const D: usize> {
    step: Option<u64>,
    z: Vec<f64>,
    sums: Vec<[f64; D]>,
}

impl<const D: usize> Default for StepNoise<D> {
    fn default() -> Self {
        StepNoise {
            step: None,
            z: Vec::new(),
            sums: Vec::new(),
        }
    }
}

/// One contacting pair's correction: x_i += dx - dv h, v_i += dv; j gets the opposite. `t` is
/// the in-step contact interval (for free-path tracking).
#[derive(Clone, Copy, Debug)]
struct Corr<const D: usize> {
    i: u32,
    j: u32,
    t: [f64; 2],
    dx: [f64; D],
    dv: [f64; D],
}

/// One half of a contacting pair's correction, for the particle `p` it moves:
/// x_p += ex, v_p += dv (the pair's i gets (dx - dv h, dv), its j the negatives: negation is
/// exact, so x_j + (-ex) is x_j - ex bit for bit).
#[derive(Clone, Copy, Debug)]
struct Half<const D: usize> {
    p: u32,
    ex: [f64; D],
    dv: [f64; D],
}

/// One pair's correction from separation r = x_i - x_j and g = v_i - v_j (None: no contact
/// within the step).
#[inline(always)]
fn pair_eval<const D: usize>(
    prop: &PairPropagator,
    d: f64,
    i: usize,
    j: usize,
    r: [f64; D],
    g: [f64; D],
) -> Option<Corr<D>> {
    let rho2: f64 = r.iter().map(|a| a * a).sum();
    let rho = rho2.sqrt();
    let inv = 1.0 / rho;
    let e: [f64; D] = std::array::from_fn(|k| r[k] * inv);
    let gn: f64 = (0..D).map(|k| g[k] * e[k]).sum();
    let ns = prop.normal(d - rho, -gn)?;
    let mut dx: [f64; D] = std::array::from_fn(|k| -0.5 * ns.ddelta * e[k]);
    let mut dv: [f64; D] = std::array::from_fn(|k| -0.5 * ns.du * e[k]);
    if D > 1 && prop.has_tangential() {
        let gt: [f64; D] = std::array::from_fn(|k| g[k] - gn * e[k]);
        let gt_abs = gt.iter().map(|a| a * a).sum::<f64>().sqrt();
        let (a, b) = prop.tangential(gt_abs, &ns);
        for k in 0..D {
            dv[k] += 0.5 * a * gt[k];
            dx[k] += 0.5 * b * gt[k];
        }
    }
    Some(Corr {
        i: i as u32,
        j: j as u32,
        t: [ns.t_on, ns.t_off],
        dx,
        dv,
    })
}

/// [`drift_block`] (from 0) and then the gathered kick of the same particles
/// (`CounterBlocks::kick_gathered`: particle i takes the normals of slot `ids[i]` of `z`), in
/// one pass: (the largest displacement squared, the largest |v|^2 after the kick), the bits of
/// the two calls one after the other.
#[allow(clippy::too_many_arguments)]
fn drift_kick_block<const D: usize>(
    x: &mut [[f64; D]],
    v: &mut [[f64; D]],
    r: &[[f64; D]],
    c: [f64; D],
    h: f64,
    ids: &[u32],
    z: &[f64],
    k: &CounterBlocks<'_>,
) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if D == 2
        && x.len() == v.len()
        && x.len() == r.len()
        && x.len() == ids.len()
        && std::arch::is_x86_feature_detected!("avx2")
    {
        let c: &[f64] = &c;
        // SAFETY: AVX2 is available (checked just above); the four slices have equal lengths
        // (the ids are checked against z in the loop).
        return unsafe {
            drift_kick2_avx2(
                x.as_flattened_mut(),
                v.as_flattened_mut(),
                r.as_flattened(),
                [c[0], c[1]],
                h,
                ids,
                z,
                k.sigma(),
            )
        };
    }
    let m = drift_block(x, v, r, c, h, 0.0);
    (m, k.kick_gathered(v, ids, z))
}

/// [`drift_kick_block`] in 2D with AVX2: four particles a round, each drifted as
/// [`drift2_avx2`] drifts it and then kicked as the gathered kick kicks it (v + sigma z, a
/// product and a sum, never fused; |v|^2 as vx^2 + vy^2), so the same bits; both maxima per
/// lane with `max_pd` from 0 and folded as those two fold them. An id whose normals are not
/// inside `z` panics before its round writes anything.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn drift_kick2_avx2(
    x: &mut [f64],
    v: &mut [f64],
    r: &[f64],
    c: [f64; 2],
    h: f64,
    ids: &[u32],
    z: &[f64],
    sigma: f64,
) -> (f64, f64) {
    use std::arch::x86_64::*;
    const AHEAD: usize = super::noise::GATHER_AHEAD;
    let len = x.len();
    let n = ids.len();
    assert!(v.len() == len && r.len() == len && len == 2 * n);
    let (xp, vp, rp, zp) = (x.as_mut_ptr(), v.as_mut_ptr(), r.as_ptr(), z.as_ptr());
    let slots = z.len() / 2;
    let zz = |id: u32| _mm_loadu_pd(zp.add(2 * id as usize));
    let cv = _mm256_setr_pd(c[0], c[1], c[0], c[1]);
    let hv = _mm256_set1_pd(h);
    let s = _mm256_set1_pd(sigma);
    let mut m = _mm256_setzero_pd();
    let mut mk = _mm256_setzero_pd();
    let mut i = 0;
    while i + 4 <= n {
        if i + AHEAD + 4 <= n {
            for q in 0..4 {
                _mm_prefetch::<_MM_HINT_T0>(
                    zp.wrapping_add(2 * *ids.get_unchecked(i + AHEAD + q) as usize) as *const i8,
                );
            }
        }
        let q = [
            *ids.get_unchecked(i),
            *ids.get_unchecked(i + 1),
            *ids.get_unchecked(i + 2),
            *ids.get_unchecked(i + 3),
        ];
        assert!(
            (q[0].max(q[1]).max(q[2]).max(q[3]) as usize) < slots,
            "drift_kick_block: a particle id past the normals"
        );
        let k = 2 * i;
        // The drift (drift2_avx2's round).
        let [v0, v1, d2] = drift_round(xp, vp, rp, k, cv, hv);
        m = _mm256_max_pd(d2, m);
        // The kick (the gathered kick's operations) of the drifted velocities.
        let z0 = _mm256_set_m128d(zz(q[1]), zz(q[0]));
        let z1 = _mm256_set_m128d(zz(q[3]), zz(q[2]));
        let w0 = _mm256_add_pd(v0, _mm256_mul_pd(s, z0));
        let w1 = _mm256_add_pd(v1, _mm256_mul_pd(s, z1));
        _mm256_storeu_pd(vp.add(k), w0);
        _mm256_storeu_pd(vp.add(k + 4), w1);
        mk = _mm256_max_pd(
            _mm256_hadd_pd(_mm256_mul_pd(w0, w0), _mm256_mul_pd(w1, w1)),
            mk,
        );
        i += 4;
    }
    let mut lanes = [0.0f64; 4];
    let mut kl = [0.0f64; 4];
    _mm256_storeu_pd(lanes.as_mut_ptr(), m);
    _mm256_storeu_pd(kl.as_mut_ptr(), mk);
    // The rest, one particle at a time into lane 0 (as the two portable loops).
    while i < n {
        let k = 2 * i;
        let d2 = drift_one_flat(x, v, r, k, c, h);
        if d2 > lanes[0] {
            lanes[0] = d2;
        }
        let id = ids[i] as usize;
        let mut a2 = 0.0;
        for q in 0..2 {
            v[k + q] += sigma * z[2 * id + q];
            a2 += v[k + q] * v[k + q];
        }
        if a2 > kl[0] {
            kl[0] = a2;
        }
        i += 1;
    }
    (largest(&lanes), largest(&kl))
}

/// Skin of the 2D neighbour list, in diameters.
pub const SKIN_DIAMETERS: f64 = 0.25;

/// The checkpoint payload (postcard-encoded by [`RfmSim::state_bytes`]).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RfmState {
    pub dim: u32,
    pub step: u64,
    /// Positions, N * dim, particle-major. 1D: unwrapped and ordered; 2D: not wrapped since
    /// the last list build.
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    /// 2D: positions at the last neighbour-list build (wrapped); empty in 1D.
    pub x_ref: Vec<f64>,
    pub max_disp2: f64,
    pub rng: RngPosition,
    /// Free-path tracking (contact counts, open paths, accumulators) when requested.
    pub free_paths: Option<FreePathAcc>,
}

/// The dimension-generic simulation core.
pub struct Core<const D: usize> {
    pub l: f64,
    pub d: f64,
    pub h: f64,
    prop: PairPropagator,
    kicks: Kicks,
    skin: f64,
    pub x: Vec<[f64; D]>,
    pub v: Vec<[f64; D]>,
    x_ref: Vec<[f64; D]>,
    max_disp2: f64,
    /// The run's stream (continues the [`RunRng`] that drew the initial state).
    pub rng: WordStream,
    pub step: u64,
    /// How the noise is drawn (1: from `rng`; 2 and 3: counter-addressed by particle, see
    /// [`Kicks::kick_counter`]; 4: by storage slot in large 2D runs, see [`slot_noise`]).
    stream: StreamVersion,
    nl: NeighbourList<D>,
    /// This step's pair corrections, in pair order (one step on one thread).
    corr: Vec<Corr<D>>,
    /// This step's pair corrections per work block of pairs (several threads; see
    /// [`pair_blocks`]).
    corr_blocks: Vec<Vec<Corr<D>>>,
    /// The pair blocks of this step's parallel pair pass (the first `pair_nb` of
    /// `corr_blocks` and `half_blocks`).
    pair_nb: usize,
    /// The same corrections as halves, per pair block and per particle block of
    /// [`Core::drift_block_len`] particles, each list in pair order (several threads): the particle
    /// blocks apply them in parallel, each particle its own halves in pair order.
    half_blocks: Vec<Vec<Vec<Half<D>>>>,
    /// 1D: this step's candidate ring pairs (scratch).
    cand: Vec<u32>,
    /// Neighbour-list builds so far (diagnostic, not part of the state).
    pub builds: u64,
    /// Free-path / post-collision velocity tracking (None: no work in the step).
    fp: Option<Box<FreePaths<D>>>,
    /// Storage order: empty when particle i is stored at index i; else the particle
    /// stored at each index (`ids`) and where each particle is stored (`at`). See
    /// [`sort_by_cell`](Self::sort_by_cell).
    ids: Vec<u32>,
    at: Vec<u32>,
    /// Never store the particles by cell (a test's reference).
    keep_order: bool,
    /// Particles stored by cell: the normals of two steps, in slot order (see
    /// [`noise`](Self::noise)).
    noise: [StepNoise<D>; 2],
    /// Scratch of the sort: cells, cell starts, the new order, a gathered array.
    sort_cell: Vec<u32>,
    sort_start: Vec<u32>,
    sort_ids: Vec<u32>,
    sort_tmp: Vec<[f64; D]>,
    /// Stored by cell: the grid of the last sort and where each of its cells starts.
    cell_grid: Option<(usize, f64)>,
    cell_starts: Vec<u32>,
}

impl<const D: usize> Core<D> {
    fn new(
        cfg: &RfmConfig,
        x: Vec<[f64; D]>,
        v: Vec<[f64; D]>,
        rng: RunRng,
        stream: StreamVersion,
    ) -> Self {
        let h = cfg.dt();
        let law = ContactLaw::from_config(cfg);
        let mut kicks = Kicks::new(cfg.noise_strength, cfg.mass, h);
        if stream != StreamVersion::V1 {
            kicks.set_seed(rng.position().seed);
        }
        if slot_noise::<D>(stream, x.len()) {
            kicks.set_block(SLOT_KICK_BLOCK);
        }
        let mut c = Core {
            l: cfg.box_length(),
            d: cfg.diameter(),
            h,
            prop: PairPropagator::new(&law, cfg.reduced_mass(), h),
            kicks,
            skin: SKIN_DIAMETERS * cfg.diameter(),
            x,
            v,
            x_ref: Vec::new(),
            max_disp2: 0.0,
            rng: WordStream::from_rng(&rng),
            step: 0,
            stream,
            nl: NeighbourList::default(),
            corr: Vec::new(),
            corr_blocks: Vec::new(),
            pair_nb: 0,
            half_blocks: Vec::new(),
            cand: Vec::new(),
            builds: 0,
            fp: None,
            ids: Vec::new(),
            at: Vec::new(),
            keep_order: false,
            noise: Default::default(),
            sort_cell: Vec::new(),
            sort_start: Vec::new(),
            sort_ids: Vec::new(),
            sort_tmp: Vec::new(),
            cell_grid: None,
            cell_starts: Vec::new(),
        };
        if D > 1 {
            c.rebuild();
        }
        c
    }

    /// Wrap positions, take them as reference, build the list.
    fn rebuild(&mut self) {
        let l = self.l;
        if let Some(fp) = self.fp.as_mut() {
            let ids = &self.ids;
            for (i, p) in self.x.iter_mut().enumerate() {
                let id = if ids.is_empty() { i } else { ids[i] as usize };
                for k in 0..D {
                    let w = wrap(p[k], l);
                    fp.shift(id, k, w - p[k]);
                    p[k] = w;
                }
            }
        } else {
            for p in self.x.iter_mut() {
                for k in 0..D {
                    p[k] = wrap(p[k], l);
                }
            }
        }
        self.x_ref.clone_from(&self.x);
        self.max_disp2 = 0.0;
        if self.by_cell() {
            self.sort_by_cell();
        } else {
            // Particle order again (a sorted run now on one thread): the list below must be
            // built in particle order (or by cell at this build), never in an older order.
            self.restore_order();
        }
        self.build_from_ref();
    }

    /// Particles per block of the drift pass (and of the halves of the pair pass).
    fn drift_block_len(&self) -> usize {
        if self.gathered() {
            SORTED_DRIFT_BLOCK
        } else {
            self.kicks.counter_blocks().block()
        }
    }

    /// Whether the particles are kept stored by cell (decided at each list build; free-path
    /// tracking maps storage indices to particles): 2D runs of at least
    /// [`PARALLEL_MIN_PARTICLES`] of
    /// - stream version 4, always (its noise is addressed by storage slot, so the order is
    ///   part of the trajectory: never a function of the thread count);
    /// - stream versions 2 and 3 stepping on a pool of several threads (on one thread the
    ///   gathered normals cost more than the order saves: 3 % at N = 27 000); either way
    ///   gives the same bits.
    fn by_cell(&self) -> bool {
        D > 1
            && self.stream != StreamVersion::V1
            && !self.keep_order
            && self.x.len() >= PARALLEL_MIN_PARTICLES
            && (self.slot_noise() || rayon::current_num_threads() > 1)
    }

    /// See [`slot_noise`].
    fn slot_noise(&self) -> bool {
        slot_noise::<D>(self.stream, self.x.len())
    }

    /// Whether the kicks gather each particle's normals from a buffer of the step's normals
    /// in particle order (particles stored by cell, stream versions 2 and 3); with version 4
    /// a slot's normal is its own, made where it is used.
    fn gathered(&self) -> bool {
        !self.ids.is_empty() && !self.slot_noise()
    }

    /// Store the particles in the order of their cells in the neighbour list's grid (at a
    /// list build, positions equal to the references), particle numbers increasing within
    /// a cell. A thread's pairs then reach mostly the particles of its own blocks, which
    /// its core wrote in the last drift (in the particles' random numbering, every pair
    /// pass read lines that the other core had just written, and every drift wrote lines
    /// the other core had read).
    ///
    /// Versions 2 and 3: the run is the same bits in any storage order: the list built from this order has
    /// the pairs of the list built in particle order, in the same order (each cell's chain
    /// runs in increasing particle number either way, and the cells in the same order); a
    /// pair of two cells may be stored the other way round (i in the lower cell), which
    /// negates r, g and the correction exactly (IEEE negation; round() is symmetric), so
    /// each particle gets the same halves in the same order. (One exception, of no
    /// consequence: a component of r that is exactly 0 is +0 both ways round, so a zero
    /// component of that pair's correction may come with the other sign, which changes a
    /// sum only where the position or velocity component it is added to is exactly -0.) The kicks take each
    /// particle's own slot's normal ([`noise`](Self::noise)); sums over particles run in
    /// particle order ([`by_id`](Self::by_id)); maxima do not see the order. Version 4:
    /// the particle stored in slot t takes slot t's normal, so this order (a function of
    /// the references alone) is part of the trajectory ([`slot_noise`]).
    fn sort_by_cell(&mut self) {
        let n = self.x.len();
        let Some((nc, side)) = cell_grid::<D>(n, self.l, self.d + self.skin) else {
            self.restore_order();
            return;
        };
        if self.ids.is_empty() {
            self.ids = (0..n as u32).collect();
            self.at = self.ids.clone();
        }
        let ncells = nc.pow(D as u32);
        self.sort_cell.clear();
        self.sort_cell
            .extend(self.x_ref.iter().map(|p| cell_index(p, nc, side) as u32));
        self.sort_start.clear();
        self.sort_start.resize(ncells + 1, 0);
        for &c in &self.sort_cell {
            self.sort_start[c as usize + 1] += 1;
        }
        for c in 0..ncells {
            self.sort_start[c + 1] += self.sort_start[c];
        }
        self.sort_ids.clear();
        self.sort_ids.resize(n, 0);
        for p in 0..n {
            let c = self.sort_cell[self.at[p] as usize] as usize;
            let t = self.sort_start[c];
            self.sort_start[c] += 1;
            self.sort_ids[t as usize] = p as u32;
        }
        // Index t now holds particle sort_ids[t], stored at at[sort_ids[t]] before.
        let at = &self.at;
        let from = |t: usize| at[self.sort_ids[t] as usize] as usize;
        self.sort_tmp.clear();
        self.sort_tmp.extend((0..n).map(|t| self.x[from(t)]));
        std::mem::swap(&mut self.x, &mut self.sort_tmp);
        self.sort_tmp.clear();
        self.sort_tmp.extend((0..n).map(|t| self.v[from(t)]));
        std::mem::swap(&mut self.v, &mut self.sort_tmp);
        self.x_ref.clone_from(&self.x);
        std::mem::swap(&mut self.ids, &mut self.sort_ids);
        for (t, &p) in self.ids.iter().enumerate() {
            self.at[p as usize] = t as u32;
        }
        // After the placement each cell's counter stands at the next cell's start.
        self.cell_starts.clear();
        self.cell_starts.push(0);
        self.cell_starts
            .extend_from_slice(&self.sort_start[..ncells]);
        self.cell_grid = Some((nc, side));
    }

    /// Store particle i at index i again (and rebuild the list in that order: the same
    /// pairs, so not counted as a build).
    #[cfg(test)]
    fn unsort(&mut self) {
        if self.restore_order() && D > 1 {
            self.nl.build(&self.x_ref, self.l, self.d + self.skin);
        }
    }

    /// Store particle i at index i again (the list is left to the caller); whether the
    /// order changed.
    fn restore_order(&mut self) -> bool {
        self.cell_grid = None;
        if self.ids.is_empty() {
            return false;
        }
        self.x = self.by_id(&self.x).into_owned();
        self.v = self.by_id(&self.v).into_owned();
        self.x_ref = self.by_id(&self.x_ref).into_owned();
        self.ids.clear();
        self.at.clear();
        true
    }

    /// A per-particle array in particle order.
    fn by_id<'a>(&self, a: &'a [[f64; D]]) -> std::borrow::Cow<'a, [[f64; D]]> {
        if self.ids.is_empty() {
            return std::borrow::Cow::Borrowed(a);
        }
        let mut out = vec![[0.0; D]; a.len()];
        for (p, &i) in a.iter().zip(&self.ids) {
            out[i as usize] = *p;
        }
        std::borrow::Cow::Owned(out)
    }

    /// Set the positions from an array in particle order.
    fn set_x_by_id(&mut self, x: Vec<[f64; D]>) {
        self.x = if self.ids.is_empty() {
            x
        } else {
            self.ids.iter().map(|&p| x[p as usize]).collect()
        };
    }

    /// Start (or stop) free-path tracking (in any storage order: the tracker maps storage
    /// indices to particles).
    fn set_free_paths(&mut self, fp: Option<Box<FreePaths<D>>>) {
        self.fp = fp;
    }

    /// Particles stored by cell with version-2 normals ([`gathered`](Self::gathered)): make the
    /// normals of step `step` (all slots, in slot order,
    /// and each kick block's sum, exactly as the kick would draw and sum them) unless they
    /// are there. The fused pass makes those of two steps on, block by block.
    fn noise(&mut self, step: u64, par: bool) {
        let buf = &mut self.noise[(step % 2) as usize];
        if buf.step == Some(step) {
            return;
        }
        let n = self.x.len();
        buf.z.resize(n * D, 0.0);
        buf.sums.resize(n.div_ceil(KICK_BLOCK), [0.0; D]);
        let k = self.kicks.counter_blocks();
        debug_assert_eq!(k.block(), KICK_BLOCK);
        let mut jobs: Vec<_> = buf
            .z
            .chunks_mut(KICK_BLOCK * D)
            .zip(buf.sums.iter_mut())
            .enumerate()
            .collect();
        let parts = if par { rayon::current_num_threads() } else { 1 };
        run_parts(&mut jobs, parts, &|(b, (z, sum))| {
            **sum = k.normals::<D>(step, *b, z)
        });
        buf.step = Some(step);
    }

    fn build_from_ref(&mut self) {
        let reach = self.d + self.skin;
        match self.cell_grid {
            // Stored by cell at this build: the list by cell ranges, on the threads.
            Some((nc, _)) if !self.ids.is_empty() => {
                let parts = if self.parallel() {
                    rayon::current_num_threads()
                } else {
                    1
                };
                self.nl
                    .build_by_cell(&self.x_ref, self.l, reach, nc, &self.cell_starts, parts)
            }
            _ => self.nl.build(&self.x_ref, self.l, reach),
        }
        self.builds += 1;
    }

    /// Largest speed squared.
    fn vmax2(&self) -> f64 {
        self.v
            .iter()
            .map(|p| p.iter().map(|a| a * a).sum::<f64>())
            .fold(0.0, f64::max)
    }

    /// Free-path tracking: record one contacting pair's in-step contact interval (kept out of
    /// line so that the untracked pair loop stays as it was).
    #[cold]
    #[inline(never)]
    fn track_pair(&mut self, i: usize, j: usize, t_on: f64, t_off: f64) {
        if let Some(fp) = self.fp.as_mut() {
            fp.push(i, j, t_on, t_off, &self.x, &self.v, &self.ids);
        }
    }

    /// One pair's contribution from separation r = x_i - x_j and g = v_i - v_j.
    #[inline(always)]
    fn pair(&mut self, i: usize, j: usize, r: [f64; D], g: [f64; D]) {
        let Some(c) = pair_eval(&self.prop, self.d, i, j, r, g) else {
            return;
        };
        if self.fp.is_some() {
            self.track_pair(i, j, c.t[0], c.t[1]);
        }
        self.corr.push(c);
    }

    /// Whether this step runs on the current rayon pool: N of at least
    /// [`PARALLEL_MIN_PARTICLES`] and a pool of several threads. Both ways give the same bits.
    fn parallel(&self) -> bool {
        self.x.len() >= PARALLEL_MIN_PARTICLES && rayon::current_num_threads() > 1
    }

    /// The 2D pair pass on the current rayon pool: each work block of pairs ([`pair_blocks`])
    /// collects its corrections in pair order; free-path tracking then sees them in pair
    /// order (before any is applied, as in the one-thread pass).
    fn pair_pass_parallel(&mut self, vmax: f64) {
        self.corr.clear();
        let cut = self.d + 2.5 * vmax * self.h;
        let cut2 = cut * cut;
        let pairs = &self.nl.pairs;
        let np = pairs.len();
        let nb = pair_blocks(np, rayon::current_num_threads());
        self.pair_nb = nb;
        if self.corr_blocks.len() < nb {
            self.corr_blocks.resize_with(nb, Vec::new);
        }
        if self.half_blocks.len() < nb {
            self.half_blocks.resize_with(nb, Vec::new);
        }
        let db = self.drift_block_len();
        let npb = self.x.len().div_ceil(db);
        let (x, v, prop, d, h) = (&self.x, &self.v, &self.prop, self.d, self.h);
        let mut jobs: Vec<_> = (0..nb)
            .map(|k| &pairs[pair_block(np, nb, k)])
            .zip(self.corr_blocks[..nb].iter_mut())
            .zip(self.half_blocks[..nb].iter_mut())
            .collect();
        run_parts(
            &mut jobs,
            rayon::current_num_threads(),
            &|((ps, out), halves): &mut (
                (&[super::neighbours::Pair<D>], &mut Vec<Corr<D>>),
                &mut Vec<Vec<Half<D>>>,
            )| {
                out.clear();
                halves.resize_with(npb, Vec::new);
                for hb in halves.iter_mut() {
                    hb.clear();
                }
                for p in ps.iter() {
                    let (i, j) = (p.i as usize, p.j as usize);
                    let r: [f64; D] = std::array::from_fn(|k| x[i][k] - x[j][k] + p.shift[k]);
                    let rho2: f64 = r.iter().map(|a| a * a).sum();
                    if rho2 >= cut2 {
                        continue;
                    }
                    let g: [f64; D] = std::array::from_fn(|k| v[i][k] - v[j][k]);
                    if let Some(c) = pair_eval(prop, d, i, j, r, g) {
                        let ex: [f64; D] = std::array::from_fn(|k| c.dx[k] - c.dv[k] * h);
                        halves[i / db].push(Half {
                            p: c.i,
                            ex,
                            dv: c.dv,
                        });
                        halves[j / db].push(Half {
                            p: c.j,
                            ex: ex.map(|a| -a),
                            dv: c.dv.map(|a| -a),
                        });
                        out.push(c);
                    }
                }
            },
        );
        for b in self.corr_blocks[nb..].iter_mut() {
            b.clear();
        }
        for b in self.half_blocks[nb..].iter_mut() {
            b.clear();
        }
        if let Some(fp) = self.fp.as_mut() {
            for c in self.corr_blocks[..nb].iter().flatten() {
                let (i, j) = (c.i as usize, c.j as usize);
                fp.push(i, j, c.t[0], c.t[1], &self.x, &self.v, &self.ids);
            }
        }
    }

    /// Collect this step's pair corrections from the kicked state (list or ring).
    fn pair_pass(&mut self, vmax: f64) {
        self.corr.clear();
        let n = self.x.len();
        if D == 1 {
            // Ring pairs (i, i+1) and (n-1, 0) that can touch within the step
            // (gap < d + 2 h |g|): a branch-free test eight pairs at a time, then the few
            // candidates in order.
            let mut cand = std::mem::take(&mut self.cand);
            cand.clear();
            let (x, v) = (self.x.as_flattened(), self.v.as_flattened());
            let (d, h2) = (self.d, 2.0 * self.h);
            const W: usize = 8;
            let m = n - 1;
            let mut i0 = 0;
            while i0 + W <= m {
                let mut near = [false; W];
                for j in 0..W {
                    let i = i0 + j;
                    near[j] = !(x[i + 1] - x[i] >= d + h2 * (v[i] - v[i + 1]).abs());
                }
                if near.iter().any(|&b| b) {
                    for j in 0..W {
                        if near[j] {
                            cand.push((i0 + j) as u32);
                        }
                    }
                }
                i0 += W;
            }
            for i in i0..m {
                if !(x[i + 1] - x[i] >= d + h2 * (v[i] - v[i + 1]).abs()) {
                    cand.push(i as u32);
                }
            }
            if !(x[0] + self.l - x[m] >= d + h2 * (v[m] - v[0]).abs()) {
                cand.push(m as u32);
            }
            for &i in &cand {
                let i = i as usize;
                let (j, wrap_l) = if i + 1 == n {
                    (0, self.l)
                } else {
                    (i + 1, 0.0)
                };
                let gap = self.x[j][0] + wrap_l - self.x[i][0];
                let mut r = [0.0; D];
                r[0] = -gap;
                let mut g = [0.0; D];
                g[0] = self.v[i][0] - self.v[j][0];
                self.pair(i, j, r, g);
            }
            self.cand = cand;
            return;
        }
        // A pair can touch within the step only if rho < d + |g| h <= d + 2 vmax h.
        let cut = self.d + 2.5 * vmax * self.h;
        let cut2 = cut * cut;
        let pairs = std::mem::take(&mut self.nl.pairs);
        for p in &pairs {
            let (i, j) = (p.i as usize, p.j as usize);
            let r: [f64; D] = std::array::from_fn(|k| self.x[i][k] - self.x[j][k] + p.shift[k]);
            let rho2: f64 = r.iter().map(|a| a * a).sum();
            if rho2 >= cut2 {
                continue;
            }
            let g: [f64; D] = std::array::from_fn(|k| self.v[i][k] - self.v[j][k]);
            self.pair(i, j, r, g);
        }
        self.nl.pairs = pairs;
    }

    /// This step's kicks, without the symmetrising shift c (pair flows see velocity
    /// differences only; the shift is subtracted in the drift): (c, largest |v|^2).
    fn kick_now(&mut self, par: bool) -> ([f64; D], f64) {
        if self.kicks.active() {
            if self.gathered() {
                let step = self.step;
                self.noise(step, par);
                let buf = &self.noise[(step % 2) as usize];
                let k = self.kicks.counter_blocks();
                let ids = &self.ids;
                let mut jobs: Vec<_> = self
                    .v
                    .chunks_mut(KICK_BLOCK)
                    .zip(ids.chunks(KICK_BLOCK))
                    .map(|(v, i)| (v, i, 0.0))
                    .collect();
                let parts = if par { rayon::current_num_threads() } else { 1 };
                run_parts(&mut jobs, parts, &|(v, i, m)| {
                    *m = k.kick_gathered(v, i, &buf.z)
                });
                return k.combine(
                    buf.sums.iter().zip(&jobs).map(|(s, j)| (*s, j.2)),
                    self.x.len(),
                );
            }
            if self.stream == StreamVersion::V1 {
                self.kicks.kick(&mut self.rng, &mut self.v)
            } else {
                self.kicks.kick_counter(self.step, &mut self.v, par)
            }
        } else {
            ([0.0; D], if D > 1 { self.vmax2() } else { 0.0 })
        }
    }

    /// Whether [`advance`](Self::advance) kicks step s + 1 in the drift pass of step s:
    /// version-2 noise (a function of (step, slot), so drawing it particle block by
    /// particle block after the drift changes nothing) and no free-path tracking (which reads
    /// the whole state between the drift and the next kick).
    fn fusable(&self) -> bool {
        self.stream != StreamVersion::V1 && self.kicks.active() && self.fp.is_none()
    }

    /// The rest of the step after its kicks `kicked` = (c, largest |v|^2): the rebuild
    /// check, the pair pass, the corrections and the drift; with `kick_next`, the drift pass
    /// also kicks the next step block by block and returns its (c, largest |v|^2) (each
    /// particle drifted before it is kicked, the kicks' block sums combined in block order:
    /// the values the next step's own kick would give).
    fn finish_step(&mut self, kicked: ([f64; D], f64), kick_next: bool) -> ([f64; D], f64) {
        let par = self.parallel();
        let (c, vmax2) = kicked;
        let vmax = if D > 1 {
            // Bound on the largest shifted speed.
            vmax2.sqrt() + c.iter().map(|a| a * a).sum::<f64>().sqrt()
        } else {
            0.0
        };
        if D > 1 {
            if 2.0 * self.max_disp2.sqrt() + 6.0 * vmax * self.h > self.skin {
                self.rebuild();
            }
        }
        if let Some(fp) = self.fp.as_mut() {
            fp.c = c;
        }
        let par_pairs = par && D > 1;
        if par_pairs {
            self.pair_pass_parallel(vmax);
        } else {
            self.pair_pass(vmax);
        }
        let h = self.h;
        if par_pairs || kick_next {
            return self.drift_pass(c, par, par_pairs, kick_next);
        }
        // A pair's (dx, dv) enters as x += dx - dv h, v += dv now, so that the drift below
        // with the corrected velocity gives x + (v - c) h + dx. Always in pair order.
        self.apply_corrections();
        if D > 1 {
            // Drift and the largest displacement since the list build.
            self.max_disp2 =
                drift_block(&mut self.x, &mut self.v, &self.x_ref, c, h, self.max_disp2);
        } else {
            drift_1d(&mut self.x, &mut self.v, c, h);
        }
        if let Some(fp) = self.fp.as_mut() {
            fp.post(&self.x, &self.v, &self.at, h, self.step);
        }
        self.step += 1;
        ([0.0; D], 0.0)
    }

    /// This step's corrections (one thread's list), in pair order.
    fn apply_corrections(&mut self) {
        let h = self.h;
        let (x, v) = (&mut self.x, &mut self.v);
        for c in &self.corr {
            let (i, j) = (c.i as usize, c.j as usize);
            for k in 0..D {
                let ex = c.dx[k] - c.dv[k] * h;
                x[i][k] += ex;
                v[i][k] += c.dv[k];
                x[j][k] -= ex;
                v[j][k] -= c.dv[k];
            }
        }
    }

    /// The corrections and the drift of this step in particle blocks of
    /// [`drift_block_len`](Self::drift_block_len)
    /// (on the pool's threads with `par`, each thread the same blocks every step), and with
    /// `kick_next` the next step's kicks of each block after its drift. With `halves` (the
    /// parallel pair pass's) each block applies its particles' halves (pair blocks in order,
    /// each in pair order: every particle's updates in pair order, as one thread applies
    /// them) before its drift; else one thread applies the corrections in pair order first.
    fn drift_pass(
        &mut self,
        c: [f64; D],
        par: bool,
        halves: bool,
        kick_next: bool,
    ) -> ([f64; D], f64) {
        if !halves {
            self.apply_corrections();
        }
        let h = self.h;
        let n = self.x.len();
        let next = self.step + 1;
        // Stored by cell with version-2 normals (gathered from a buffer).
        let sorted = self.gathered();
        if kick_next && sorted {
            self.noise(next, par);
        }
        let hb: &[Vec<Vec<Half<D>>>] = if halves {
            &self.half_blocks[..self.pair_nb]
        } else {
            &[]
        };
        let kicker: Option<CounterBlocks<'_>> = kick_next.then(|| self.kicks.counter_blocks());
        let db = self.drift_block_len();
        // Drift blocks per kick block.
        let per_kick = KICK_BLOCK / db;
        let mut rs = self.x_ref.chunks(db);
        let mut idb = self.ids.chunks(db);
        // Particles stored by cell: kick from the normals of step next, and make those of
        // step next + 1 (the buffer of the step just kicked) block by block.
        let (now, ahead) = {
            let [a, b] = &mut self.noise;
            if next % 2 == 0 {
                (&*a, b)
            } else {
                (&*b, a)
            }
        };
        let mut aheads = if kick_next && sorted {
            let n = self.x.len();
            ahead.step = Some(next + 1);
            ahead.z.resize(n * D, 0.0);
            ahead.sums.resize(n.div_ceil(KICK_BLOCK), [0.0; D]);
            Some(
                ahead
                    .z
                    .chunks_mut(KICK_BLOCK * D)
                    .zip(ahead.sums.iter_mut()),
            )
        } else {
            None
        };
        let mut jobs: Vec<DriftJob<'_, D>> = self
            .x
            .chunks_mut(db)
            .zip(self.v.chunks_mut(db))
            .enumerate()
            .map(|(b, (x, v))| DriftJob {
                b,
                x,
                v,
                r: if D > 1 { rs.next().unwrap_or(&[]) } else { &[] },
                ids: idb.next().unwrap_or(&[]),
                // The first drift block of each kick block makes that kick block's normals.
                ahead: if b % per_kick == 0 {
                    aheads.as_mut().and_then(|a| a.next())
                } else {
                    None
                },
                m: 0.0,
                kick: ([0.0; D], 0.0),
            })
            .collect();
        let zn = &now.z;
        let kicker = kicker.as_ref();
        let parts = if par { rayon::current_num_threads() } else { 1 };
        run_parts(&mut jobs, parts, &|j: &mut DriftJob<'_, D>| {
            let base = j.b * db;
            for hs in hb {
                for e in &hs[j.b] {
                    let p = e.p as usize - base;
                    for k in 0..D {
                        j.x[p][k] += e.ex[k];
                        j.v[p][k] += e.dv[k];
                    }
                }
            }
            match kicker {
                // Stored by cell: the drift and the gathered kick in one pass.
                Some(k) if sorted && D > 1 => {
                    let (m, mk) = drift_kick_block(j.x, j.v, j.r, c, h, j.ids, zn, k);
                    j.m = m;
                    j.kick = ([0.0; D], mk);
                }
                // Each slot's own normals (particles in particle order, or stream version 4):
                // each particle drifted just before its kick, in one pass (the drift block is
                // the kick block `j.b`).
                Some(k) if D > 1 => {
                    debug_assert_eq!(db, k.block());
                    let (kick, m) = k.drift_kick(next, j.b, j.x, j.v, j.r, c, h);
                    j.m = m;
                    j.kick = kick;
                }
                _ if D > 1 => j.m = drift_block(j.x, j.v, j.r, c, h, 0.0),
                _ => drift_1d(j.x, j.v, c, h),
            }
            if let Some(k) = kicker {
                if D > 1 && !sorted {
                    // Kicked with the drift above.
                } else if sorted {
                    if D == 1 {
                        j.kick = ([0.0; D], k.kick_gathered(j.v, j.ids, zn));
                    }
                    if let Some((z, sum)) = j.ahead.as_mut() {
                        **sum = k.normals::<D>(next + 1, j.b / per_kick, z);
                    }
                } else {
                    j.kick = k.kick(next, j.b, j.v);
                }
            }
        });
        let m = jobs
            .iter()
            .fold(0.0, |a: f64, j| if j.m > a { j.m } else { a });
        let kicked = match kicker {
            // The sums of the kick blocks in block order (made with the normals), the
            // largest |v|^2 of all (the same as the fused kick's blocks give).
            Some(k) if sorted => {
                let (c, _) = k.combine(now.sums.iter().map(|s| (*s, 0.0)), n);
                let m = jobs
                    .iter()
                    .fold(0.0, |a: f64, j| if j.kick.1 > a { j.kick.1 } else { a });
                (c, m)
            }
            Some(k) => k.combine(jobs.iter().map(|j| j.kick), n),
            None => ([0.0; D], 0.0),
        };
        drop(jobs);
        if D > 1 {
            self.max_disp2 = if m > self.max_disp2 {
                m
            } else {
                self.max_disp2
            };
        }
        if let Some(fp) = self.fp.as_mut() {
            fp.post(&self.x, &self.v, &self.at, h, self.step);
        }
        self.step += 1;
        kicked
    }

    /// Advance by `steps` steps. Stream version 2 without free-path tracking kicks step
    /// s + 1 in step s's drift pass (one pass over the particles fewer per step); the state
    /// between calls is the same bits as one step at a time.
    pub fn advance(&mut self, steps: u64) {
        if steps == 0 {
            return;
        }
        // The steps' passes run on a team of the pool's threads (same bits), when there
        // are parallel passes: 2D, or 1D with the version-2 kicks.
        let passes = D > 1 || (self.kicks.active() && self.stream != StreamVersion::V1);
        team::with_team(self.parallel() && passes, || {
            let fuse = self.fusable();
            let mut kicked = self.kick_now(self.parallel());
            for s in 0..steps {
                let more = s + 1 < steps;
                let next = self.finish_step(kicked, fuse && more);
                if more {
                    kicked = if fuse {
                        next
                    } else {
                        self.kick_now(self.parallel())
                    };
                }
            }
        })
    }

    pub fn mean_velocity(&self) -> [f64; D] {
        let mut m = [0.0; D];
        for v in self.by_id(&self.v).iter() {
            for k in 0..D {
                m[k] += v[k];
            }
        }
        m.map(|a| a / self.v.len() as f64)
    }

    /// (2.19): (1/N) sum_i |v_i - <v>|^2.
    pub fn temperature(&self) -> f64 {
        let m = self.mean_velocity();
        self.by_id(&self.v)
            .iter()
            .map(|v| (0..D).map(|k| (v[k] - m[k]).powi(2)).sum::<f64>())
            .sum::<f64>()
            / self.v.len() as f64
    }

    /// The pair corrections of one step from the current state, without the kicks
    /// (test hook: list versus brute force).
    #[cfg(test)]
    fn corrections(&mut self, brute_force: bool) -> Vec<([f64; D], [f64; D])> {
        let n = self.x.len();
        if brute_force {
            self.corr.clear();
            for i in 0..n {
                for j in i + 1..n {
                    let r: [f64; D] = std::array::from_fn(|k| {
                        super::neighbours::min_image(self.x[i][k] - self.x[j][k], self.l)
                    });
                    let g: [f64; D] = std::array::from_fn(|k| self.v[i][k] - self.v[j][k]);
                    self.pair(i, j, r, g);
                }
            }
        } else {
            let vmax = self.vmax2().sqrt();
            self.pair_pass(vmax);
        }
        let mut out = vec![([0.0; D], [0.0; D]); n];
        for c in &self.corr {
            let (i, j, dx, dv) = (c.i, c.j, c.dx, c.dv);
            for k in 0..D {
                out[i as usize].0[k] += dx[k];
                out[i as usize].1[k] += dv[k];
                out[j as usize].0[k] -= dx[k];
                out[j as usize].1[k] -= dv[k];
            }
        }
        out
    }
}

enum Inner {
    D1(Core<1>),
    D2(Core<2>),
}

/// A Random Force Model run.
pub struct RfmSim {
    cfg: RfmConfig,
    inner: Inner,
}

fn flatten<const D: usize>(a: &[[f64; D]]) -> Vec<f64> {
    a.iter().flat_map(|p| p.iter().copied()).collect()
}

fn unflatten<const D: usize>(a: &[f64]) -> Vec<[f64; D]> {
    a.chunks_exact(D)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect()
}

impl RfmSim {
    /// A new run drawing as stream version `stream` prescribes (see
    /// [`crate::rng::StreamVersion`]): the initial state is drawn from the run's sequential
    /// stream in every version; version 1 draws the noise from it too, version 2 draws the
    /// noise counter-addressed by (step, slot) ([`Kicks::kick_counter`]), so that a run can
    /// step on several threads with the same output.
    pub fn with_stream(cfg: RfmConfig, seed: u64, stream: StreamVersion) -> Result<Self, SimError> {
        let (x, v, rng) = Self::initial(&cfg, seed)?;
        Self::assemble(cfg, x, v, rng, stream)
    }

    /// A new run of stream version 1 (see [`with_stream`](Self::with_stream)): validated
    /// config, the initial layout and velocities (spec 1.9: each component
    /// 0.1 U(-0.5, 0.5) m/s, mean removed) drawn from the run's stream.
    pub fn new(cfg: RfmConfig, seed: u64) -> Result<Self, SimError> {
        Self::with_stream(cfg, seed, StreamVersion::V1)
    }

    /// The validated config's initial positions and velocities, and the stream after them.
    fn initial(cfg: &RfmConfig, seed: u64) -> Result<(Vec<f64>, Vec<f64>, RunRng), SimError> {
        cfg.validate().map_err(|e| SimError::Config(e.join("; ")))?;
        for w in cfg.warnings() {
            tracing::warn!("{w}");
        }
        let mut rng = RunRng::new(seed);
        let n = cfg.n_particles;
        let dim = cfg.dim as usize;
        let x = initial_positions(cfg, &mut rng)?;
        let mut v: Vec<f64> = (0..n * dim).map(|_| 0.1 * (rng.f64() - 0.5)).collect();
        for k in 0..dim {
            let m = v.iter().skip(k).step_by(dim).sum::<f64>() / n as f64;
            for a in v.iter_mut().skip(k).step_by(dim) {
                *a -= m;
            }
        }
        Ok((x, v, rng))
    }

    /// A run from explicit positions and velocities (flat, particle-major; 1D positions must
    /// be increasing within one period). For tests and special set-ups.
    pub fn from_parts(
        cfg: RfmConfig,
        seed: u64,
        x: Vec<f64>,
        v: Vec<f64>,
    ) -> Result<Self, SimError> {
        cfg.validate().map_err(|e| SimError::Config(e.join("; ")))?;
        let n = cfg.n_particles * cfg.dim as usize;
        if x.len() != n || v.len() != n {
            return Err(SimError::Config(
                "from_parts: positions and velocities must have N * dim entries".into(),
            ));
        }
        Self::assemble(cfg, x, v, RunRng::new(seed), StreamVersion::V1)
    }

    fn assemble(
        cfg: RfmConfig,
        x: Vec<f64>,
        v: Vec<f64>,
        rng: RunRng,
        stream: StreamVersion,
    ) -> Result<Self, SimError> {
        let inner = match cfg.dim {
            1 => Inner::D1(Core::new(&cfg, unflatten(&x), unflatten(&v), rng, stream)),
            _ => Inner::D2(Core::new(&cfg, unflatten(&x), unflatten(&v), rng, stream)),
        };
        Ok(RfmSim { cfg, inner })
    }

    /// The run's random stream version.
    pub fn stream_version(&self) -> StreamVersion {
        match &self.inner {
            Inner::D1(c) => c.stream,
            Inner::D2(c) => c.stream,
        }
    }

    pub fn config(&self) -> &RfmConfig {
        &self.cfg
    }

    /// Advance by `steps` time steps (any chunking gives the same trajectory).
    pub fn advance(&mut self, steps: u64) {
        match &mut self.inner {
            Inner::D1(c) => c.advance(steps),
            Inner::D2(c) => c.advance(steps),
        }
    }

    pub fn step(&self) -> u64 {
        match &self.inner {
            Inner::D1(c) => c.step,
            Inner::D2(c) => c.step,
        }
    }

    pub fn time(&self) -> f64 {
        self.step() as f64 * self.cfg.dt()
    }

    /// Granular temperature (2.19) in the centre-of-mass frame (m^2/s^2, no M/2).
    pub fn temperature(&self) -> f64 {
        match &self.inner {
            Inner::D1(c) => c.temperature(),
            Inner::D2(c) => c.temperature(),
        }
    }

    /// Total momentum M sum_i v_i, one entry per component.
    pub fn momentum(&self) -> Vec<f64> {
        let m = self.cfg.mass * self.cfg.n_particles as f64;
        match &self.inner {
            Inner::D1(c) => c.mean_velocity().iter().map(|a| a * m).collect(),
            Inner::D2(c) => c.mean_velocity().iter().map(|a| a * m).collect(),
        }
    }

    /// Positions (flat, particle-major). 1D: unwrapped; 2D: wrapped at the last list build.
    pub fn positions(&self) -> Vec<f64> {
        match &self.inner {
            Inner::D1(c) => flatten(&c.x),
            Inner::D2(c) => flatten(&c.by_id(&c.x)),
        }
    }

    /// Velocities (flat, particle-major).
    pub fn velocities(&self) -> Vec<f64> {
        match &self.inner {
            Inner::D1(c) => flatten(&c.v),
            Inner::D2(c) => flatten(&c.by_id(&c.v)),
        }
    }

    /// Number of 2D neighbour-list builds so far (diagnostic).
    pub fn list_builds(&self) -> u64 {
        match &self.inner {
            Inner::D1(_) => 0,
            Inner::D2(c) => c.builds,
        }
    }

    /// Start tracking contact counts for free paths and post-collision velocities (spec 2.9,
    /// 2.3; [`super::freepath`]). Call before the first step.
    pub fn track_free_paths(&mut self, cfg: FreePathConfig) {
        let (n, dim) = (self.cfg.n_particles, self.cfg.dim);
        let acc = FreePathAcc::new(cfg, n, dim);
        match &mut self.inner {
            Inner::D1(c) => c.fp = Some(Box::new(FreePaths::new(acc))),
            Inner::D2(c) => c.set_free_paths(Some(Box::new(FreePaths::new(acc)))),
        }
    }

    /// The free-path settings being tracked, if any.
    pub fn free_path_config(&self) -> Option<&FreePathConfig> {
        match &self.inner {
            Inner::D1(c) => c.fp.as_ref().map(|f| &f.acc.cfg),
            Inner::D2(c) => c.fp.as_ref().map(|f| &f.acc.cfg),
        }
    }

    /// The free-path tracker's state, if any (tests and diagnostics).
    pub fn free_path_acc(&self) -> Option<&FreePathAcc> {
        match &self.inner {
            Inner::D1(c) => c.fp.as_ref().map(|f| &f.acc),
            Inner::D2(c) => c.fp.as_ref().map(|f| &f.acc),
        }
    }

    /// Histogram rows ("free_path", "post_collision_velocity") and free-path moments, the
    /// errors from the blocks of a run of `samples` samples.
    pub fn free_path_rows(&self, samples: u64) -> (Vec<HistRow>, Vec<FreePathMomentRow>) {
        self.free_path_acc()
            .map(|a| a.rows(samples))
            .unwrap_or_default()
    }

    /// The checkpoint payload.
    pub fn state_bytes(&self) -> Vec<u8> {
        let st = match &self.inner {
            Inner::D1(c) => RfmState {
                dim: 1,
                step: c.step,
                x: flatten(&c.x),
                v: flatten(&c.v),
                x_ref: Vec::new(),
                max_disp2: 0.0,
                rng: c.rng.position(),
                free_paths: c.fp.as_ref().map(|f| f.acc.clone()),
            },
            Inner::D2(c) => RfmState {
                dim: 2,
                step: c.step,
                x: flatten(&c.by_id(&c.x)),
                v: flatten(&c.by_id(&c.v)),
                x_ref: flatten(&c.by_id(&c.x_ref)),
                max_disp2: c.max_disp2,
                rng: c.rng.position(),
                free_paths: c.fp.as_ref().map(|f| f.acc.clone()),
            },
        };
        let mut bytes = postcard::to_stdvec(&st).expect("state serialises");
        // The stream version follows the state (postcard varint of its number); version 1
        // writes nothing, so its bytes are those of granular before stream versions.
        let stream = self.stream_version();
        if stream != StreamVersion::V1 {
            bytes.extend(postcard::to_stdvec(&stream.number()).expect("u32 serialises"));
        }
        bytes
    }

    /// Rebuild a run from its config and a checkpoint payload.
    pub fn from_state_bytes(cfg: RfmConfig, bytes: &[u8]) -> Result<Self, SimError> {
        cfg.validate().map_err(|e| e.join("; "))?;
        let (st, rest): (RfmState, &[u8]) = postcard::take_from_bytes(bytes)
            .map_err(|e| format!("checkpoint payload does not decode: {e}"))?;
        // Nothing after the state: a version-1 run (every checkpoint before stream versions).
        let stream = if rest.is_empty() {
            StreamVersion::V1
        } else {
            let (number, tail): (u32, &[u8]) = postcard::take_from_bytes(rest)
                .map_err(|e| format!("checkpoint's stream version does not decode: {e}"))?;
            if !tail.is_empty() {
                return Err(
                    "checkpoint payload has trailing bytes after its stream version".into(),
                );
            }
            StreamVersion::try_from(number).map_err(|e| format!("checkpoint: {e}"))?
        };
        let n = cfg.n_particles * cfg.dim as usize;
        if st.dim != cfg.dim || st.x.len() != n || st.v.len() != n {
            return Err("checkpoint does not match the run's dimension or particle count".into());
        }
        // A largest displacement that is not a finite number >= 0 cannot come from a step
        // (a NaN would also keep the neighbour list from ever being rebuilt).
        if !(st.max_disp2.is_finite() && st.max_disp2 >= 0.0) {
            return Err("checkpoint's largest displacement is not a finite number >= 0".into());
        }
        if let Some(a) = &st.free_paths {
            if a.in_contact.len() != cfg.n_particles || a.start.len() != n || a.dim != cfg.dim {
                return Err("checkpoint's free-path state does not match the run".into());
            }
        }
        let rng = RunRng::restore(&st.rng);
        let inner = match cfg.dim {
            1 => {
                let mut c = Core::<1>::new(&cfg, unflatten(&st.x), unflatten(&st.v), rng, stream);
                c.step = st.step;
                c.fp = st.free_paths.map(|a| Box::new(FreePaths::new(a)));
                Inner::D1(c)
            }
            _ => {
                if st.x_ref.len() != n {
                    return Err("checkpoint lacks the neighbour-list reference".into());
                }
                let mut c =
                    Core::<2>::new(&cfg, unflatten(&st.x_ref), unflatten(&st.v), rng, stream);
                c.set_x_by_id(unflatten(&st.x));
                c.max_disp2 = st.max_disp2;
                c.step = st.step;
                c.set_free_paths(st.free_paths.map(|a| Box::new(FreePaths::new(a))));
                c.builds = 0;
                Inner::D2(c)
            }
        };
        Ok(RfmSim { cfg, inner })
    }
}

/// Initial positions (flat) for the configured layout (spec 1.9).
fn initial_positions(cfg: &RfmConfig, rng: &mut RunRng) -> Result<Vec<f64>, SimError> {
    let n = cfg.n_particles;
    let l = cfg.box_length();
    let d = cfg.diameter();
    if cfg.dim == 1 {
        let s = l / n as f64;
        return Ok((0..n).map(|i| (i as f64 + 0.5) * s).collect());
    }
    let sp = d * (1.0 + 1e-3);
    let mut x = Vec::with_capacity(2 * n);
    match cfg.initial_layout {
        InitialLayout::Square | InitialLayout::Hexagonal => {
            let hex = cfg.initial_layout == InitialLayout::Hexagonal;
            let per_row = (l / sp).floor() as usize;
            let pitch = if hex { sp * 3f64.sqrt() / 2.0 } else { sp };
            // The sites (`RfmConfig::validate` refuses a bed too small): hex rows alternate
            // offsets, in an even number of rows.
            let sites = cfg.lattice_sites().unwrap_or(0);
            let rows = sites.checked_div(per_row).unwrap_or(0);
            if sites < n {
                return Err(SimError::Config(format!(
                    "initial_layout: {n} particles do not fit a {:?} bed ({sites} sites)",
                    cfg.initial_layout,
                )));
            }
            let mut count = 0;
            'outer: for r in 0..rows {
                let off = if hex && r % 2 == 1 { 0.5 * sp } else { 0.0 };
                for c in 0..per_row {
                    if count == n {
                        break 'outer;
                    }
                    x.push(0.5 * sp + off + c as f64 * sp);
                    x.push(0.5 * sp + r as f64 * pitch);
                    count += 1;
                }
            }
            if count < n {
                return Err(SimError::Config(format!(
                    "initial_layout: {n} particles do not fit the bed"
                )));
            }
        }
        InitialLayout::Uniform => {
            // Random sequential addition (the rule and how it runs: `super::layout`).
            let par = n >= PARALLEL_MIN_PARTICLES && rayon::current_num_threads() > 1;
            x = super::layout::uniform(n, l, sp, rng, par)?;
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests;
