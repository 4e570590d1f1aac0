//! The run's ChaCha8 stream, generated in bulk for the noise (the same words, in the same
//! order, as [`crate::rng::RunRng`] from the same position: rand_chacha's `ChaCha8Rng`,
//! 64-bit block counter, stream 0, 64-bit words = pairs of little-endian 32-bit words).
//!
//! The block function runs on 16 blocks at a time, one block per vector lane (AVX-512 when
//! the CPU has it, else AVX2 or the portable path, chosen at run time by `pick`: all give
//! identical words, checked by `matches_run_rng`), and fills the caller's slice directly, so
//! a step's normals cost no per-word bookkeeping. The AVX2 path is written with intrinsics
//! (the auto-vectorised one ran at 0.42x rand_chacha's speed; this one at ~1.2x); measure it
//! with `cargo run --release --example bench_rng`.

use std::sync::OnceLock;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{RngPosition, RunRng};

use super::chunked::{BlockFn, Chunked, CHUNK};

/// Blocks per chunk (16 words of 32 bits each).
const CHUNK_BLOCKS: usize = CHUNK / 8;

/// (key, stream, first block, out): 16 blocks of ChaCha8 with the 64-bit `stream` in state
/// words 14-15 (rand_chacha's `set_stream`; the run's sequential stream is stream 0).
type ChunkFn = unsafe fn(&[u32; 8], u64, u64, &mut [u32]);

/// ChaCha8's blocks of stream 0 under a seed's key.
pub struct ChaCha8Blocks {
    key: [u32; 8],
    gen: ChunkFn,
}

impl BlockFn for ChaCha8Blocks {
    const WORDS: usize = 8;

    #[inline]
    fn chunk(&self, first: u128, out: &mut [u64]) {
        debug_assert_eq!(out.len(), CHUNK);
        // SAFETY: `pick` chose a block function this CPU runs; out is one chunk (16 blocks).
        // The 64-bit block counter wraps, as rand_chacha's.
        unsafe { (self.gen)(&self.key, 0, first as u64, as_u32(out)) };
        fix_endian(out);
    }
}

/// The run's ChaCha8 words, served from a chunk of 16 blocks.
pub type WordStream = Chunked<ChaCha8Blocks>;

impl Chunked<ChaCha8Blocks> {
    /// The stream of `rng` (a ChaCha8 one), continuing exactly where `rng` stands.
    pub fn from_rng(rng: &RunRng) -> Self {
        debug_assert_eq!(rng.generator(), super::Generator::ChaCha8);
        Self::at(&rng.position())
    }

    /// The stream at a saved position.
    pub fn at(pos: &RngPosition) -> Self {
        let blocks = ChaCha8Blocks {
            key: key_of(pos.seed),
            gen: pick(),
        };
        Chunked::new(pos, blocks)
    }
}

/// The ChaCha8 key of a run's seed (rand_chacha's `ChaCha8Rng::seed_from_u64`).
pub fn key_of(seed: u64) -> [u32; 8] {
    let seed_bytes = ChaCha8Rng::seed_from_u64(seed).get_seed();
    std::array::from_fn(|k| u32::from_le_bytes(seed_bytes[4 * k..4 * k + 4].try_into().unwrap()))
}

/// Counter-addressed words: `out[i]` is 64-bit word `8 * first_block + i` of ChaCha8 with
/// `key` and `stream` (words of blocks `first_block ..`, as rand_chacha's `ChaCha8Rng` with
/// `set_stream(stream)` and `set_word_pos(16 * first_block)` would serve them). Any length;
/// whole chunks go straight into `out`.
pub fn fill_counter(key: &[u32; 8], stream: u64, first_block: u64, out: &mut [u64]) {
    static GEN: OnceLock<ChunkFn> = OnceLock::new();
    let gen = *GEN.get_or_init(pick);
    let mut block = first_block;
    let mut chunks = out.chunks_exact_mut(CHUNK);
    for c in &mut chunks {
        unsafe { gen(key, stream, block, as_u32(c)) };
        fix_endian(c);
        block = block.wrapping_add(CHUNK_BLOCKS as u64);
    }
    let rest = chunks.into_remainder();
    if !rest.is_empty() {
        let mut tmp = [0u64; CHUNK];
        unsafe { gen(key, stream, block, as_u32(&mut tmp)) };
        fix_endian(&mut tmp);
        let k = rest.len();
        rest.copy_from_slice(&tmp[..k]);
    }
}

fn as_u32(w: &mut [u64]) -> &mut [u32] {
    // SAFETY: u64 has the size and a stricter alignment of two u32.
    unsafe { std::slice::from_raw_parts_mut(w.as_mut_ptr() as *mut u32, w.len() * 2) }
}

/// The stream's 64-bit word is `lo | hi << 32` of consecutive 32-bit words: the memory
/// layout on little-endian hosts; swap the halves elsewhere.
#[inline(always)]
fn fix_endian(w: &mut [u64]) {
    if cfg!(target_endian = "big") {
        for a in w.iter_mut() {
            *a = a.rotate_left(32);
        }
    }
}

fn pick() -> ChunkFn {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return chunk_avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            return chunk_avx2;
        }
    }
    chunk_portable
}

/// AVX-512: the 16 state words of 16 blocks in 16 registers (one block per 32-bit lane),
/// then a 16 x 16 transpose by in-lane unpacks and 128-bit shuffles.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn chunk_avx512(key: &[u32; 8], stream: u64, block: u64, out: &mut [u32]) {
    use std::arch::x86_64::*;
    assert!(out.len() >= 256);
    const C: [u32; 4] = [0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574];
    let lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let lo0 = _mm512_set1_epi32(block as u32 as i32);
    let lo = _mm512_add_epi32(lo0, lanes);
    // Carry into the high word where the low word wrapped (lo < lo0, unsigned).
    let carry = _mm512_cmplt_epu32_mask(lo, lo0);
    let hi0 = _mm512_set1_epi32((block >> 32) as u32 as i32);
    let hi = _mm512_mask_add_epi32(hi0, carry, hi0, _mm512_set1_epi32(1));
    let mut init = [_mm512_setzero_si512(); 16];
    for k in 0..4 {
        init[k] = _mm512_set1_epi32(C[k] as i32);
    }
    for k in 0..8 {
        init[4 + k] = _mm512_set1_epi32(key[k] as i32);
    }
    init[12] = lo;
    init[13] = hi;
    init[14] = _mm512_set1_epi32(stream as u32 as i32);
    init[15] = _mm512_set1_epi32((stream >> 32) as u32 as i32);
    let mut x = init;
    macro_rules! qr {
        ($a:expr, $b:expr, $c:expr, $d:expr) => {
            x[$a] = _mm512_add_epi32(x[$a], x[$b]);
            x[$d] = _mm512_rol_epi32::<16>(_mm512_xor_si512(x[$d], x[$a]));
            x[$c] = _mm512_add_epi32(x[$c], x[$d]);
            x[$b] = _mm512_rol_epi32::<12>(_mm512_xor_si512(x[$b], x[$c]));
            x[$a] = _mm512_add_epi32(x[$a], x[$b]);
            x[$d] = _mm512_rol_epi32::<8>(_mm512_xor_si512(x[$d], x[$a]));
            x[$c] = _mm512_add_epi32(x[$c], x[$d]);
            x[$b] = _mm512_rol_epi32::<7>(_mm512_xor_si512(x[$b], x[$c]));
        };
    }
    for _ in 0..4 {
        qr!(0, 4, 8, 12);
        qr!(1, 5, 9, 13);
        qr!(2, 6, 10, 14);
        qr!(3, 7, 11, 15);
        qr!(0, 5, 10, 15);
        qr!(1, 6, 11, 12);
        qr!(2, 7, 8, 13);
        qr!(3, 4, 9, 14);
    }
    for k in 0..16 {
        x[k] = _mm512_add_epi32(x[k], init[k]);
    }
    // t[g][r], 128-bit lane l: words 4g..4g+3 of block 4l + r.
    let mut t = [[_mm512_setzero_si512(); 4]; 4];
    for g in 0..4 {
        let a0 = _mm512_unpacklo_epi32(x[4 * g], x[4 * g + 1]);
        let a1 = _mm512_unpackhi_epi32(x[4 * g], x[4 * g + 1]);
        let a2 = _mm512_unpacklo_epi32(x[4 * g + 2], x[4 * g + 3]);
        let a3 = _mm512_unpackhi_epi32(x[4 * g + 2], x[4 * g + 3]);
        t[g][0] = _mm512_unpacklo_epi64(a0, a2);
        t[g][1] = _mm512_unpackhi_epi64(a0, a2);
        t[g][2] = _mm512_unpacklo_epi64(a1, a3);
        t[g][3] = _mm512_unpackhi_epi64(a1, a3);
    }
    let p = out.as_mut_ptr() as *mut __m512i;
    for r in 0..4 {
        let u0 = _mm512_shuffle_i32x4::<0x44>(t[0][r], t[1][r]);
        let u1 = _mm512_shuffle_i32x4::<0xEE>(t[0][r], t[1][r]);
        let u2 = _mm512_shuffle_i32x4::<0x44>(t[2][r], t[3][r]);
        let u3 = _mm512_shuffle_i32x4::<0xEE>(t[2][r], t[3][r]);
        _mm512_storeu_si512(p.add(r), _mm512_shuffle_i32x4::<0x88>(u0, u2));
        _mm512_storeu_si512(p.add(4 + r), _mm512_shuffle_i32x4::<0xDD>(u0, u2));
        _mm512_storeu_si512(p.add(8 + r), _mm512_shuffle_i32x4::<0x88>(u1, u3));
        _mm512_storeu_si512(p.add(12 + r), _mm512_shuffle_i32x4::<0xDD>(u1, u3));
    }
}

/// AVX2, written out: 8 blocks per register set (one block per 32-bit lane of the 16 state
/// registers), rotations by 16 and 8 as byte shuffles, by 12 and 7 as shift/or, then two
/// 8 x 8 transposes in registers (unpacks and 128-bit permutes) and full-width stores.
/// Two such groups of 8 blocks make the chunk.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn chunk_avx2(key: &[u32; 8], stream: u64, block: u64, out: &mut [u32]) {
    assert!(out.len() >= 256);
    avx2_8(key, stream, block, out.as_mut_ptr());
    avx2_8(
        key,
        stream,
        block.wrapping_add(8),
        out.as_mut_ptr().add(128),
    );
}

/// ChaCha8 blocks `block .. block + 8` (with `stream`) into `out[0..128]`, block after block.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn avx2_8(key: &[u32; 8], stream: u64, block: u64, out: *mut u32) {
    use std::arch::x86_64::*;
    const C: [u32; 4] = [0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574];
    // Byte shuffles that rotate each 32-bit lane left by 16 and by 8.
    let r16 = _mm256_setr_epi8(
        2, 3, 0, 1, 6, 7, 4, 5, 10, 11, 8, 9, 14, 15, 12, 13, 2, 3, 0, 1, 6, 7, 4, 5, 10, 11, 8, 9,
        14, 15, 12, 13,
    );
    let r8 = _mm256_setr_epi8(
        3, 0, 1, 2, 7, 4, 5, 6, 11, 8, 9, 10, 15, 12, 13, 14, 3, 0, 1, 2, 7, 4, 5, 6, 11, 8, 9, 10,
        15, 12, 13, 14,
    );
    let b: [u64; 8] = std::array::from_fn(|j| block.wrapping_add(j as u64));
    let lo = _mm256_setr_epi32(
        b[0] as i32,
        b[1] as i32,
        b[2] as i32,
        b[3] as i32,
        b[4] as i32,
        b[5] as i32,
        b[6] as i32,
        b[7] as i32,
    );
    let hi = _mm256_setr_epi32(
        (b[0] >> 32) as i32,
        (b[1] >> 32) as i32,
        (b[2] >> 32) as i32,
        (b[3] >> 32) as i32,
        (b[4] >> 32) as i32,
        (b[5] >> 32) as i32,
        (b[6] >> 32) as i32,
        (b[7] >> 32) as i32,
    );
    let mut init = [_mm256_setzero_si256(); 16];
    for k in 0..4 {
        init[k] = _mm256_set1_epi32(C[k] as i32);
    }
    for k in 0..8 {
        init[4 + k] = _mm256_set1_epi32(key[k] as i32);
    }
    init[12] = lo;
    init[13] = hi;
    init[14] = _mm256_set1_epi32(stream as u32 as i32);
    init[15] = _mm256_set1_epi32((stream >> 32) as u32 as i32);
    let mut x = init;
    macro_rules! rot {
        ($v:expr, $n:literal) => {
            _mm256_or_si256(
                _mm256_slli_epi32::<$n>($v),
                _mm256_srli_epi32::<{ 32 - $n }>($v),
            )
        };
    }
    macro_rules! qr {
        ($a:expr, $b:expr, $c:expr, $d:expr) => {
            x[$a] = _mm256_add_epi32(x[$a], x[$b]);
            x[$d] = _mm256_shuffle_epi8(_mm256_xor_si256(x[$d], x[$a]), r16);
            x[$c] = _mm256_add_epi32(x[$c], x[$d]);
            x[$b] = rot!(_mm256_xor_si256(x[$b], x[$c]), 12);
            x[$a] = _mm256_add_epi32(x[$a], x[$b]);
            x[$d] = _mm256_shuffle_epi8(_mm256_xor_si256(x[$d], x[$a]), r8);
            x[$c] = _mm256_add_epi32(x[$c], x[$d]);
            x[$b] = rot!(_mm256_xor_si256(x[$b], x[$c]), 7);
        };
    }
    for _ in 0..4 {
        qr!(0, 4, 8, 12);
        qr!(1, 5, 9, 13);
        qr!(2, 6, 10, 14);
        qr!(3, 7, 11, 15);
        qr!(0, 5, 10, 15);
        qr!(1, 6, 11, 12);
        qr!(2, 7, 8, 13);
        qr!(3, 4, 9, 14);
    }
    for k in 0..16 {
        x[k] = _mm256_add_epi32(x[k], init[k]);
    }
    // Half h: state words 8h .. 8h + 8 of the 8 blocks, transposed to 8 rows of one block.
    let p = out as *mut __m256i;
    for h in 0..2 {
        let y = &x[8 * h..8 * h + 8];
        // t[g][r], 128-bit half l: words 8h + 4g .. + 4 of block 4l + r.
        let mut t = [[_mm256_setzero_si256(); 4]; 2];
        for g in 0..2 {
            let a0 = _mm256_unpacklo_epi32(y[4 * g], y[4 * g + 1]);
            let a1 = _mm256_unpackhi_epi32(y[4 * g], y[4 * g + 1]);
            let a2 = _mm256_unpacklo_epi32(y[4 * g + 2], y[4 * g + 3]);
            let a3 = _mm256_unpackhi_epi32(y[4 * g + 2], y[4 * g + 3]);
            t[g][0] = _mm256_unpacklo_epi64(a0, a2);
            t[g][1] = _mm256_unpackhi_epi64(a0, a2);
            t[g][2] = _mm256_unpacklo_epi64(a1, a3);
            t[g][3] = _mm256_unpackhi_epi64(a1, a3);
        }
        for r in 0..4 {
            // Block r: row 2 r + h of 32 bytes; block 4 + r: row 2 (4 + r) + h.
            _mm256_storeu_si256(
                p.add(2 * r + h),
                _mm256_permute2x128_si256::<0x20>(t[0][r], t[1][r]),
            );
            _mm256_storeu_si256(
                p.add(2 * (4 + r) + h),
                _mm256_permute2x128_si256::<0x31>(t[0][r], t[1][r]),
            );
        }
    }
}

unsafe fn chunk_portable(key: &[u32; 8], stream: u64, block: u64, out: &mut [u32]) {
    for q in 0..4 {
        blocks::<4>(
            key,
            stream,
            block.wrapping_add(4 * q as u64),
            &mut out[64 * q..64 * (q + 1)],
        );
    }
}

#[inline(always)]
fn qr<const L: usize>(x: &mut [[u32; L]; 16], a: usize, b: usize, c: usize, d: usize) {
    for j in 0..L {
        x[a][j] = x[a][j].wrapping_add(x[b][j]);
        x[d][j] = (x[d][j] ^ x[a][j]).rotate_left(16);
        x[c][j] = x[c][j].wrapping_add(x[d][j]);
        x[b][j] = (x[b][j] ^ x[c][j]).rotate_left(12);
        x[a][j] = x[a][j].wrapping_add(x[b][j]);
        x[d][j] = (x[d][j] ^ x[a][j]).rotate_left(8);
        x[c][j] = x[c][j].wrapping_add(x[d][j]);
        x[b][j] = (x[b][j] ^ x[c][j]).rotate_left(7);
    }
}

/// ChaCha8 blocks `block .. block + L` into `out` (16 L words, block after block).
#[inline(always)]
fn blocks<const L: usize>(key: &[u32; 8], stream: u64, block: u64, out: &mut [u32]) {
    const C: [u32; 4] = [0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574];
    let mut x = [[0u32; L]; 16];
    for k in 0..4 {
        x[k] = [C[k]; L];
    }
    for k in 0..8 {
        x[4 + k] = [key[k]; L];
    }
    for j in 0..L {
        let b = block.wrapping_add(j as u64);
        x[12][j] = b as u32;
        x[13][j] = (b >> 32) as u32;
        x[14][j] = stream as u32;
        x[15][j] = (stream >> 32) as u32;
    }
    let init = x;
    for _ in 0..4 {
        qr(&mut x, 0, 4, 8, 12);
        qr(&mut x, 1, 5, 9, 13);
        qr(&mut x, 2, 6, 10, 14);
        qr(&mut x, 3, 7, 11, 15);
        qr(&mut x, 0, 5, 10, 15);
        qr(&mut x, 1, 6, 11, 12);
        qr(&mut x, 2, 7, 8, 13);
        qr(&mut x, 3, 4, 9, 14);
    }
    let out = &mut out[..16 * L];
    for k in 0..16 {
        for j in 0..L {
            out[16 * j + k] = x[k][j].wrapping_add(init[k][j]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Identical words to RunRng from fresh, mid-buffer and odd-block positions, through
    /// `u64` and `fill`, on every code path the CPU offers; positions round-trip.
    #[test]
    fn matches_run_rng() {
        for seed in [0u64, 1, 0xdead_beef_1234] {
            let mut r = RunRng::new(seed);
            for _ in 0..37 {
                r.u64();
            }
            for skip in [0usize, 1, 5, 300, 1000] {
                for _ in 0..skip {
                    r.u64();
                }
                let mut s = WordStream::from_rng(&r);
                let mut got = vec![0u64; 700];
                s.fill(&mut got[..3]);
                s.fill(&mut got[3..300]);
                for g in got[300..310].iter_mut() {
                    *g = s.u64();
                }
                s.fill(&mut got[310..]);
                let pos = s.position();
                let want: Vec<u64> = (0..700).map(|_| r.u64()).collect();
                assert_eq!(got, want, "seed {seed} skip {skip}");
                let mut t = RunRng::restore(&pos);
                let mut s2 = WordStream::at(&pos);
                for _ in 0..200 {
                    let w = r.u64();
                    assert_eq!(t.u64(), w);
                    assert_eq!(s.u64(), w);
                    assert_eq!(s2.u64(), w);
                }
            }
        }
        // Every code path the CPU offers against the portable one: several keys, streams and
        // first blocks, including wraps of the low counter word and of the whole counter.
        let mut paths: Vec<(&str, ChunkFn)> = vec![("pick", pick())];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                paths.push(("avx2", chunk_avx2));
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                paths.push(("avx512", chunk_avx512));
            }
        }
        let keys = [
            [1, 2, 3, 4, 5, 6, 7, 8],
            key_of(0),
            key_of(0xdead_beef),
            [u32::MAX; 8],
        ];
        let streams = [0u64, 1, 7, 0x1234_5678_9abc_def0, u64::MAX];
        let blocks = [
            0u64,
            5,
            u32::MAX as u64 - 3,
            u32::MAX as u64 - 15,
            u32::MAX as u64,
            (7u64 << 32) - 9,
            u64::MAX - 3,
            u64::MAX,
        ];
        for key in &keys {
            for &stream in &streams {
                for &block in &blocks {
                    let mut a = [0u32; 256];
                    unsafe { chunk_portable(key, stream, block, &mut a) };
                    for (name, f) in &paths {
                        let mut b = [0u32; 256];
                        unsafe { f(key, stream, block, &mut b) };
                        assert_eq!(a, b, "{name}: key {key:?} stream {stream} block {block}");
                    }
                }
            }
        }
    }

    /// `fill_counter` serves rand_chacha's ChaCha8 words of a given stream and word position,
    /// for lengths that end inside a chunk and first blocks that wrap the low counter word.
    #[test]
    fn counter_words_are_rand_chacha_streams() {
        use rand::RngCore;
        for (seed, stream, block) in [
            (3u64, 0u64, 0u64),
            (9, 7, 5),
            (1, u64::MAX, u32::MAX as u64 - 2),
        ] {
            let key = key_of(seed);
            let mut got = vec![0u64; 301];
            fill_counter(&key, stream, block, &mut got);
            let mut r = ChaCha8Rng::seed_from_u64(seed);
            r.set_stream(stream);
            r.set_word_pos(16 * block as u128);
            let want: Vec<u64> = (0..301).map(|_| r.next_u64()).collect();
            assert_eq!(got, want, "seed {seed} stream {stream} block {block}");
        }
    }
}
