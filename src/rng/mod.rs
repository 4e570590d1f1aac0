//! Random streams. Every run draws from a ChaCha8 stream seeded by its seed (itself derived
//! from the campaign seed and the run's identity, see `derive_seed` in the campaign plan).
//!
//! [`RunRng`] serves 64-bit words from a buffer filled in bulk (the ChaCha block function is
//! vectorised), and its position can be saved and restored exactly for checkpoints.
//! [`stream`] is that block function in bulk, also used directly by the RFM noise.

pub mod aes;
pub mod chunked;
pub mod normal;
pub mod stream;

use rand::RngCore;

use serde::{Deserialize, Serialize};

/// How a run draws its random numbers. Part of a campaign's identity: recorded in the
/// campaign when it is created, kept when it grows, so that its runs replay bit for bit.
///
/// - 1: every draw from the run's sequential ChaCha8 stream ([`RunRng`], [`stream`]).
/// - 2: as 1, except the RFM noise: ChaCha8 keyed by the run's seed and addressed by
///   (step, particle), so that a run can be split over threads with identical output.
/// - 3: as 2, except that DSMC runs draw every word (candidates and impact directions) from
///   AES-128 in counter mode ([`Generator::Aes128Ctr`]) instead of ChaCha8: the same draws
///   from other words, about three times faster to make where the CPU has VAES.
/// - 4: as 3, except the RFM noise's addressing in 2D runs of at least
///   `rfm::sim::PARALLEL_MIN_PARTICLES` particles (1D runs and smaller 2D runs draw as in 3):
///   the particles stay stored by cell on any number of threads, and the normals are
///   addressed by (step, storage slot) instead of (step, particle), in work blocks of 512
///   particles instead of 2048. The kicks then read their
///   normals where they are made, with no buffer of the step's normals and no gather, and a
///   run's threads share its particles in finer blocks. Statistically the same noise: the
///   storage order at a step is fixed by the state before it, so each particle still gets
///   fresh independent normals at every step.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[serde(try_from = "u32", into = "u32")]
pub struct StreamVersion(u32);

impl StreamVersion {
    /// The stream of every campaign made before stream versions were recorded.
    pub const V1: StreamVersion = StreamVersion(1);
    /// Counter-addressed RFM noise.
    pub const V2: StreamVersion = StreamVersion(2);
    /// DSMC words from AES-128 in counter mode.
    pub const V3: StreamVersion = StreamVersion(3);
    /// RFM noise addressed by storage slot, 2D particles stored by cell on any thread count.
    pub const V4: StreamVersion = StreamVersion(4);
    /// The version of new campaigns.
    pub const CURRENT: StreamVersion = StreamVersion::V4;

    pub fn number(self) -> u32 {
        self.0
    }

    /// Whether the RFM noise of large 2D runs is addressed by storage slot (with its
    /// 512-particle work blocks).
    pub fn rfm_slot_noise(self) -> bool {
        self.0 >= 4
    }

    /// The generator of a DSMC run's words.
    pub fn dsmc_generator(self) -> Generator {
        if self.0 >= 3 {
            Generator::Aes128Ctr
        } else {
            Generator::ChaCha8
        }
    }
}

/// The block generator behind a [`RunRng`]'s words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Generator {
    /// ChaCha8 (rand_chacha's words), [`stream::WordStream`].
    ChaCha8,
    /// AES-128 in counter mode, [`aes::AesStream`].
    Aes128Ctr,
}

enum Core {
    ChaCha8(stream::WordStream),
    Aes128Ctr(aes::AesStream),
}

impl Core {
    fn at(pos: &RngPosition, generator: Generator) -> Self {
        match generator {
            Generator::ChaCha8 => Core::ChaCha8(stream::WordStream::at(pos)),
            Generator::Aes128Ctr => Core::Aes128Ctr(aes::AesStream::at(pos)),
        }
    }

    fn position(&self) -> RngPosition {
        match self {
            Core::ChaCha8(s) => s.position(),
            Core::Aes128Ctr(s) => s.position(),
        }
    }

    fn fill(&mut self, out: &mut [u64]) {
        match self {
            Core::ChaCha8(s) => s.fill(out),
            Core::Aes128Ctr(s) => s.fill(out),
        }
    }

    fn generator(&self) -> Generator {
        match self {
            Core::ChaCha8(_) => Generator::ChaCha8,
            Core::Aes128Ctr(_) => Generator::Aes128Ctr,
        }
    }
}

/// A stream version this granular does not know (a newer granular made the campaign).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownStreamVersion(pub u32);

impl std::fmt::Display for UnknownStreamVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "random stream version {} is not known to this granular (it knows 1 to {}); \
             a newer granular made it",
            self.0,
            StreamVersion::CURRENT.0
        )
    }
}

impl std::error::Error for UnknownStreamVersion {}

impl TryFrom<u32> for StreamVersion {
    type Error = UnknownStreamVersion;
    fn try_from(v: u32) -> Result<Self, UnknownStreamVersion> {
        if (1..=StreamVersion::CURRENT.0).contains(&v) {
            Ok(StreamVersion(v))
        } else {
            Err(UnknownStreamVersion(v))
        }
    }
}

impl From<StreamVersion> for u32 {
    fn from(v: StreamVersion) -> u32 {
        v.0
    }
}

impl Default for StreamVersion {
    /// Absent from a record: the campaign predates stream versions.
    fn default() -> Self {
        StreamVersion::V1
    }
}

const BUF: usize = 256;

pub struct RunRng {
    /// The ChaCha8 block function in bulk (16 blocks at a time, vectorised; the same words as
    /// `rand_chacha::ChaCha8Rng`, checked by `words_are_rand_chacha_chacha8`), or AES-128 in
    /// counter mode.
    core: Core,
    /// Word position of `core` when `buf` was filled (in 32-bit words).
    filled_at: u128,
    buf: Box<[u64; BUF]>,
    idx: usize,
    seed: u64,
}

/// The exact position of a [`RunRng`]: enough to restore it bit for bit.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
pub struct RngPosition {
    pub seed: u64,
    pub filled_at: u128,
    pub idx: u32,
}

impl RunRng {
    /// The ChaCha8 stream of `seed`.
    pub fn new(seed: u64) -> Self {
        Self::at(seed, 0, Generator::ChaCha8)
    }

    /// The stream of `seed` from `generator`.
    pub fn with_generator(seed: u64, generator: Generator) -> Self {
        Self::at(seed, 0, generator)
    }

    /// The generator of the words.
    pub fn generator(&self) -> Generator {
        self.core.generator()
    }

    /// The stream of `seed` from word position `filled_at` (in 32-bit words), buffer filled.
    fn at(seed: u64, filled_at: u128, generator: Generator) -> Self {
        let core = Core::at(
            &RngPosition {
                seed,
                filled_at,
                idx: 0,
            },
            generator,
        );
        let mut r = RunRng {
            core,
            filled_at,
            buf: Box::new([0; BUF]),
            idx: BUF,
            seed,
        };
        r.refill();
        r
    }

    fn refill(&mut self) {
        self.filled_at = self.core.position().filled_at;
        self.core.fill(&mut self.buf[..]);
        self.idx = 0;
    }

    #[inline(always)]
    pub fn u64(&mut self) -> u64 {
        if self.idx == BUF {
            self.refill();
        }
        let x = self.buf[self.idx];
        self.idx += 1;
        x
    }

    /// The next `n` words (n <= 128) without consuming them; [`consume`](Self::consume) then
    /// takes some of them. The position is unchanged (the buffer is moved, not the stream).
    #[inline(always)]
    pub fn window(&mut self, n: usize) -> &[u64] {
        debug_assert!(n <= BUF / 2);
        if BUF - self.idx < n {
            self.shift();
        }
        // SAFETY: idx + n <= BUF after the shift.
        unsafe { self.buf.get_unchecked(self.idx..self.idx + n) }
    }

    /// Skip `n` words of the last [`window`](Self::window).
    #[inline(always)]
    pub fn consume(&mut self, n: usize) {
        self.idx += n;
        debug_assert!(self.idx <= BUF);
    }

    /// Move on by `k` >= 1 words, leaving the stream exactly as `k` calls of [`RunRng::u64`]
    /// do (buffer position and index included: a checkpoint records them), without making
    /// them.
    pub fn skip(&mut self, k: u64) {
        let buf = BUF as u128;
        let pos = self.position();
        let total = pos.idx as u128 + k as u128;
        let generator = self.generator();
        if total <= buf {
            *self = RunRng::restore_with(
                &RngPosition {
                    idx: total as u32,
                    ..pos
                },
                generator,
            );
            return;
        }
        // Each refill (at an exhausted buffer) moves the buffer on by BUF words.
        let refills = (total - 1) / buf;
        *self = RunRng::restore_with(
            &RngPosition {
                seed: pos.seed,
                filled_at: pos.filled_at + 2 * buf * refills,
                idx: (total - buf * refills) as u32,
            },
            generator,
        );
    }

    /// Move the unread words to the front of the buffer and fill the rest.
    #[cold]
    fn shift(&mut self) {
        let left = BUF - self.idx;
        self.buf.copy_within(self.idx.., 0);
        // The buffer now starts `idx` 64-bit words later in the stream.
        self.filled_at += 2 * self.idx as u128;
        self.core.fill(&mut self.buf[left..]);
        self.idx = 0;
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline(always)]
    pub fn f64(&mut self) -> f64 {
        unit_f64(self.u64())
    }

    /// Uniform in (0, 1].
    #[inline(always)]
    pub fn f64_open0(&mut self) -> f64 {
        unit_f64_open0(self.u64())
    }

    /// Uniform integer in [0, n) by multiply-high (bias below n / 2^64).
    #[inline(always)]
    pub fn below(&mut self, n: usize) -> usize {
        ((self.u64() as u128 * n as u128) >> 64) as usize
    }

    /// Two independent uniform integers in [0, n1) and [0, n2) from one word (32 bits each),
    /// exact: Lemire's multiply-shift with rejection (a rejected half, probability < n / 2^32,
    /// is redrawn from a fresh word). Falls back to [`below`](Self::below) for n >= 2^32.
    #[inline(always)]
    pub fn below_pair(&mut self, n1: usize, n2: usize) -> (usize, usize) {
        if n1 > u32::MAX as usize || n2 > u32::MAX as usize {
            return (self.below(n1), self.below(n2));
        }
        let w = self.u64();
        let a = match lemire32((w >> 32) as u32, n1 as u32) {
            Some(a) => a,
            None => loop {
                if let Some(a) = lemire32((self.u64() >> 32) as u32, n1 as u32) {
                    break a;
                }
            },
        };
        let b = match lemire32(w as u32, n2 as u32) {
            Some(b) => b,
            None => loop {
                if let Some(b) = lemire32((self.u64() >> 32) as u32, n2 as u32) {
                    break b;
                }
            },
        };
        (a as usize, b as usize)
    }

    /// Standard normal variate (ziggurat).
    #[inline(always)]
    pub fn normal(&mut self) -> f64 {
        use rand_distr::Distribution;
        rand_distr::StandardNormal.sample(self)
    }

    pub fn position(&self) -> RngPosition {
        RngPosition {
            seed: self.seed,
            filled_at: self.filled_at,
            idx: self.idx as u32,
        }
    }

    /// The ChaCha8 stream at a saved position.
    pub fn restore(pos: &RngPosition) -> Self {
        Self::restore_with(pos, Generator::ChaCha8)
    }

    /// The stream of `generator` at a saved position.
    pub fn restore_with(pos: &RngPosition, generator: Generator) -> Self {
        let mut r = RunRng::at(pos.seed, pos.filled_at, generator);
        r.idx = (pos.idx as usize).min(BUF);
        r
    }
}

/// A word as a uniform in [0, 1) (its top 53 bits), as [`RunRng::f64`].
#[inline(always)]
pub fn unit_f64(w: u64) -> f64 {
    (w >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A word as a uniform in (0, 1], as [`RunRng::f64_open0`].
#[inline(always)]
pub fn unit_f64_open0(w: u64) -> f64 {
    ((w >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Uniform in [0, n) from 32 random bits, or None when they must be redrawn (Lemire 2019).
#[inline(always)]
pub fn lemire32(x: u32, n: u32) -> Option<u32> {
    let m = x as u64 * n as u64;
    let l = m as u32;
    if l < n {
        let t = n.wrapping_neg() % n;
        if l < t {
            return None;
        }
    }
    Some((m >> 32) as u32)
}

impl RngCore for RunRng {
    fn next_u32(&mut self) -> u32 {
        (self.u64() >> 32) as u32
    }
    fn next_u64(&mut self) -> u64 {
        self.u64()
    }
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for chunk in dst.chunks_mut(8) {
            let w = self.u64().to_le_bytes();
            chunk.copy_from_slice(&w[..chunk.len()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const GENERATORS: [Generator; 2] = [Generator::ChaCha8, Generator::Aes128Ctr];

    /// Windows (which move the buffer when they reach its end) serve the same words as
    /// `u64`, and a position taken after a moved buffer restores the same stream (both
    /// generators).
    #[test]
    fn windows_are_the_stream() {
        for g in GENERATORS {
            windows_are_the_stream_of(g);
        }
    }

    fn windows_are_the_stream_of(g: Generator) {
        let mut plain = RunRng::with_generator(5, g);
        let mut win = RunRng::with_generator(5, g);
        for step in 0..5000usize {
            let n = 1 + step % 7;
            let w = win.window(n).to_vec();
            let take = 1 + step % n;
            win.consume(take);
            for (j, &x) in w.iter().enumerate().take(take) {
                assert_eq!(x, plain.u64(), "step {step} word {j}");
            }
            if step % 97 == 0 {
                win = RunRng::restore_with(&win.position(), g);
            }
            assert_eq!(win.position().seed, 5);
        }
        assert_eq!(win.u64(), plain.u64());
    }

    #[test]
    fn restore_continues_the_same_stream() {
        for g in GENERATORS {
            let mut a = RunRng::with_generator(7, g);
            for _ in 0..1000 {
                a.u64();
            }
            let pos = a.position();
            let mut b = RunRng::restore_with(&pos, g);
            assert_eq!(b.generator(), g);
            for _ in 0..2000 {
                assert_eq!(a.u64(), b.u64());
            }
        }
    }

    /// The AES words are the blocks AES-128 makes of the counters 0, 1, ... under the seed's
    /// key (checked with the `aes` crate itself), and other than ChaCha8's.
    #[test]
    fn aes_words_are_the_counter_blocks() {
        use ::aes::cipher::{generic_array::GenericArray, BlockEncrypt, KeyInit};
        for seed in [0u64, 3, u64::MAX] {
            let c = ::aes::Aes128::new(&GenericArray::from(aes::aes_key_of(seed)));
            let mut r = RunRng::with_generator(seed, Generator::Aes128Ctr);
            for n in 0..700u128 {
                let mut b = GenericArray::from(n.to_le_bytes());
                c.encrypt_block(&mut b);
                for half in b.chunks_exact(8) {
                    let want = u64::from_le_bytes(half.try_into().unwrap());
                    assert_eq!(r.u64(), want, "seed {seed} block {n}");
                }
            }
            assert_ne!(
                RunRng::with_generator(seed, Generator::Aes128Ctr).u64(),
                RunRng::new(seed).u64()
            );
        }
    }

    /// Each of 7 x 5 outcomes of `below_pair` has probability 1/35; 350k draws give counts
    /// of 10000 with standard deviation ~99: allow 5 sigma.
    #[test]
    fn below_pair_is_uniform() {
        let mut r = RunRng::new(11);
        let mut counts = [[0u32; 5]; 7];
        for _ in 0..350_000 {
            let (a, b) = r.below_pair(7, 5);
            counts[a][b] += 1;
        }
        for row in counts {
            for c in row {
                assert!((c as f64 - 10_000.0).abs() < 5.0 * 99.0, "{c}");
            }
        }
        // Lemire rejection: with n = 3 * 2^30 a quarter of the 32-bit values are rejected.
        assert_eq!(lemire32(0, 3 << 30), None);
        assert_eq!(lemire32(u32::MAX, 3 << 30), Some((3 << 30) - 1));
    }

    /// The words are rand_chacha's ChaCha8 stream (seed_from_u64, little-endian pairs of
    /// 32-bit words), from the start and from a restored position.
    #[test]
    fn words_are_rand_chacha_chacha8() {
        for seed in [0u64, 1, 42, u64::MAX] {
            let mut reference = ChaCha8Rng::seed_from_u64(seed);
            let mut r = RunRng::new(seed);
            for i in 0..5000 {
                assert_eq!(r.u64(), reference.next_u64(), "seed {seed} word {i}");
            }
            let pos = r.position();
            let mut t = RunRng::restore(&pos);
            for _ in 0..1000 {
                assert_eq!(t.u64(), reference.next_u64());
            }
        }
    }

    #[test]
    fn different_seeds_differ() {
        assert_ne!(RunRng::new(1).u64(), RunRng::new(2).u64());
    }

    /// `skip` leaves the stream exactly as that many single draws do.
    #[test]
    fn skip_is_single_draws() {
        for &skip in &[0usize, 1, 200, 255, 256, 300] {
            for (&k, g) in [1u64, 2, 55, 256, 257, 511, 512, 513, 100_000]
                .iter()
                .flat_map(|k| GENERATORS.map(|g| (k, g)))
            {
                let mut a = RunRng::with_generator(3, g);
                for _ in 0..skip {
                    a.u64();
                }
                let mut b = RunRng::restore_with(&a.position(), g);
                for _ in 0..k {
                    a.u64();
                }
                b.skip(k);
                assert_eq!(a.position(), b.position(), "skip {skip} k {k}");
                assert_eq!(a.u64(), b.u64());
            }
        }
    }
}
