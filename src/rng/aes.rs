//! AES-128 in counter mode as a stream of 64-bit words: block n of the stream is AES-128 under
//! the run's key of the 128-bit little-endian counter n, its 16 bytes two little-endian words.
//! This is Random123's "AESNI" generator (Salmon et al., SC'11, "Parallel random numbers: as
//! easy as 1, 2, 3"), which passes TestU01's BigCrush; AES-128 in counter mode is also NIST's
//! CTR_DRBG block generator. The key of a seed is the first 128 bits of its ChaCha8 key
//! ([`super::stream::key_of`], rand_core's `seed_from_u64` expansion).
//!
//! Where the CPU has VAES (with AVX2), the blocks are made here, 16 at a time in 256-bit
//! registers (about three times the speed of ChaCha8 in AVX2 on the machines we measured);
//! elsewhere by the `aes` crate (AES-NI when the CPU has it, else its constant-time software
//! AES). Both give the same words (checked against each other and FIPS-197's example).

use aes::cipher::{generic_array::GenericArray, BlockEncrypt, KeyInit};

use super::chunked::{BlockFn, Chunked, CHUNK};
use super::RngPosition;

/// The AES-128 key of a run's seed.
pub fn aes_key_of(seed: u64) -> [u8; 16] {
    let k = super::stream::key_of(seed);
    let mut key = [0u8; 16];
    for (b, w) in key.chunks_exact_mut(4).zip(k) {
        b.copy_from_slice(&w.to_le_bytes());
    }
    key
}

/// AES-128's blocks under a seed's key (made by VAES or the `aes` crate: the same blocks).
pub struct Blocks(Impl);

enum Impl {
    /// The `aes` crate's cipher.
    Crate(Box<aes::Aes128>),
    /// Round keys for the VAES path (x86-64 with VAES, AVX2 and AES-NI, detected at run time).
    #[cfg(target_arch = "x86_64")]
    Vaes(Box<[[u8; 16]; 11]>),
}

impl Blocks {
    fn new(key: &[u8; 16]) -> Self {
        #[cfg(target_arch = "x86_64")]
        if vaes_available() {
            // SAFETY: the CPU has AES-NI (checked by vaes_available).
            return Blocks(Impl::Vaes(Box::new(unsafe { x86::expand_key(key) })));
        }
        Blocks(Impl::Crate(Box::new(aes::Aes128::new(
            &GenericArray::from(*key),
        ))))
    }

    /// Blocks `first`, `first + 1`, ... into `out` (two words a block; `out.len()` a multiple
    /// of 32).
    fn fill(&self, first: u128, out: &mut [u64]) {
        debug_assert_eq!(out.len() % 32, 0);
        match &self.0 {
            Impl::Crate(c) => crate_blocks(c, first, out),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: Vaes exists only where the CPU has VAES, AVX2 and AES-NI.
            Impl::Vaes(rk) => unsafe { x86::vaes_blocks(rk, first, out) },
        }
    }
}

/// Whether the VAES path runs on this CPU.
#[cfg(target_arch = "x86_64")]
pub fn vaes_available() -> bool {
    is_x86_feature_detected!("vaes")
        && is_x86_feature_detected!("avx2")
        && is_x86_feature_detected!("aes")
}

fn crate_blocks(c: &aes::Aes128, first: u128, out: &mut [u64]) {
    let mut blocks = [GenericArray::from([0u8; 16]); 16];
    for (n, part) in out.chunks_mut(32).enumerate() {
        let base = first.wrapping_add(16 * n as u128);
        for (j, b) in blocks.iter_mut().enumerate() {
            *b = GenericArray::from(base.wrapping_add(j as u128).to_le_bytes());
        }
        c.encrypt_blocks(&mut blocks);
        for (w, b) in part.chunks_exact_mut(2).zip(&blocks) {
            w[0] = u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
            w[1] = u64::from_le_bytes(b[8..].try_into().expect("8 bytes"));
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// AES-128 key expansion (FIPS-197 5.2) with AESKEYGENASSIST.
    #[target_feature(enable = "aes")]
    pub unsafe fn expand_key(key: &[u8; 16]) -> [[u8; 16]; 11] {
        #[inline(always)]
        unsafe fn step(k: __m128i, assist: __m128i) -> __m128i {
            let t = _mm_shuffle_epi32(assist, 0xff);
            let mut k = k;
            k = _mm_xor_si128(k, _mm_slli_si128(k, 4));
            k = _mm_xor_si128(k, _mm_slli_si128(k, 4));
            k = _mm_xor_si128(k, _mm_slli_si128(k, 4));
            _mm_xor_si128(k, t)
        }
        let mut rk = [_mm_setzero_si128(); 11];
        rk[0] = _mm_loadu_si128(key.as_ptr() as *const __m128i);
        rk[1] = step(rk[0], _mm_aeskeygenassist_si128::<0x01>(rk[0]));
        rk[2] = step(rk[1], _mm_aeskeygenassist_si128::<0x02>(rk[1]));
        rk[3] = step(rk[2], _mm_aeskeygenassist_si128::<0x04>(rk[2]));
        rk[4] = step(rk[3], _mm_aeskeygenassist_si128::<0x08>(rk[3]));
        rk[5] = step(rk[4], _mm_aeskeygenassist_si128::<0x10>(rk[4]));
        rk[6] = step(rk[5], _mm_aeskeygenassist_si128::<0x20>(rk[5]));
        rk[7] = step(rk[6], _mm_aeskeygenassist_si128::<0x40>(rk[6]));
        rk[8] = step(rk[7], _mm_aeskeygenassist_si128::<0x80>(rk[7]));
        rk[9] = step(rk[8], _mm_aeskeygenassist_si128::<0x1b>(rk[8]));
        rk[10] = step(rk[9], _mm_aeskeygenassist_si128::<0x36>(rk[9]));
        let mut out = [[0u8; 16]; 11];
        for (o, k) in out.iter_mut().zip(rk) {
            _mm_storeu_si128(o.as_mut_ptr() as *mut __m128i, k);
        }
        out
    }

    /// Blocks `first`, `first + 1`, ... into `out` (a multiple of 32 words: 16 blocks, eight
    /// 256-bit registers of two blocks each, in flight at a time).
    #[target_feature(enable = "vaes,avx2,aes")]
    pub unsafe fn vaes_blocks(rk: &[[u8; 16]; 11], first: u128, out: &mut [u64]) {
        let mut k = [_mm256_setzero_si256(); 11];
        for (kk, r) in k.iter_mut().zip(rk) {
            *kk = _mm256_broadcastsi128_si256(_mm_loadu_si128(r.as_ptr() as *const __m128i));
        }
        for (n, part) in out.chunks_exact_mut(32).enumerate() {
            let base = first.wrapping_add(16 * n as u128);
            let mut b = [_mm256_setzero_si256(); 8];
            if (base as u64).checked_add(15).is_some() {
                // The 16 counters share their high half: the low halves by vector adds.
                let (lo, hi) = (base as u64 as i64, (base >> 64) as u64 as i64);
                let c = _mm256_set_epi64x(hi, lo.wrapping_add(1), hi, lo);
                for (j, x) in b.iter_mut().enumerate() {
                    let step = 2 * j as i64;
                    let ctr = _mm256_add_epi64(c, _mm256_set_epi64x(0, step, 0, step));
                    *x = _mm256_xor_si256(ctr, k[0]);
                }
            } else {
                for (j, x) in b.iter_mut().enumerate() {
                    let c0 = base.wrapping_add(2 * j as u128);
                    let c1 = c0.wrapping_add(1);
                    let ctr = _mm256_set_epi64x(
                        (c1 >> 64) as i64,
                        c1 as i64,
                        (c0 >> 64) as i64,
                        c0 as i64,
                    );
                    *x = _mm256_xor_si256(ctr, k[0]);
                }
            }
            for kr in &k[1..10] {
                for x in b.iter_mut() {
                    *x = _mm256_aesenc_epi128(*x, *kr);
                }
            }
            let p = part.as_mut_ptr() as *mut __m256i;
            for (j, x) in b.iter().enumerate() {
                _mm256_storeu_si256(p.add(j), _mm256_aesenclast_epi128(*x, k[10]));
            }
        }
    }
}

impl BlockFn for Blocks {
    const WORDS: usize = 2;

    #[inline]
    fn chunk(&self, first: u128, out: &mut [u64]) {
        debug_assert_eq!(out.len(), CHUNK);
        self.fill(first, out);
    }
}

/// The AES-128 counter-mode words of a seed, served from a chunk of 64 blocks (the
/// counterpart of [`super::stream::WordStream`]).
pub type AesStream = Chunked<Blocks>;

impl Chunked<Blocks> {
    /// The stream at a saved position (in 32-bit words, as ChaCha8's: four a block).
    pub fn at(pos: &RngPosition) -> Self {
        Chunked::new(pos, Blocks::new(&aes_key_of(pos.seed)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FIPS-197 appendix C.1: AES-128 of 00112233...ff under the key 000102...0f.
    #[test]
    fn fips_197_example() {
        let key: [u8; 16] = std::array::from_fn(|i| i as u8);
        let plain: [u8; 16] = std::array::from_fn(|i| (i as u8) * 0x11);
        let want = [
            0x69, 0xc4, 0xe0, 0xd8, 0x6a, 0x7b, 0x04, 0x30, 0xd8, 0xcd, 0xb7, 0x80, 0x70, 0xb4,
            0xc5, 0x5a,
        ];
        let first = u128::from_le_bytes(plain);
        let mut paths = vec![Blocks(Impl::Crate(Box::new(aes::Aes128::new(
            &GenericArray::from(key),
        ))))];
        #[cfg(target_arch = "x86_64")]
        if vaes_available() {
            paths.push(Blocks(Impl::Vaes(Box::new(unsafe {
                x86::expand_key(&key)
            }))));
        }
        for b in paths {
            let mut out = [0u64; 32];
            b.fill(first, &mut out);
            let mut got = [0u8; 16];
            got[..8].copy_from_slice(&out[0].to_le_bytes());
            got[8..].copy_from_slice(&out[1].to_le_bytes());
            assert_eq!(got, want);
        }
    }

    /// The VAES path makes the crate's words, for several keys and counters (one that carries
    /// into the counter's high half).
    #[test]
    fn vaes_is_the_crate() {
        #[cfg(target_arch = "x86_64")]
        if vaes_available() {
            for seed in [0u64, 1, 77, u64::MAX] {
                let key = aes_key_of(seed);
                let c = aes::Aes128::new(&GenericArray::from(key));
                let rk = unsafe { x86::expand_key(&key) };
                for first in [
                    0u128,
                    5,
                    (1u128 << 64) - 7,
                    (1u128 << 64) - 40,
                    u128::MAX - 3,
                ] {
                    let (mut a, mut b) = ([0u64; 96], [0u64; 96]);
                    crate_blocks(&c, first, &mut a);
                    unsafe { x86::vaes_blocks(&rk, first, &mut b) };
                    assert_eq!(a, b, "seed {seed} first {first}");
                }
            }
        } else {
            eprintln!("no VAES here: only the crate's path runs");
        }
    }

    /// Words served in pieces of any length, and from restored positions, are the blocks in
    /// counter order.
    #[test]
    fn positions_and_pieces_are_the_counter_stream() {
        let key = aes_key_of(9);
        let c = aes::Aes128::new(&GenericArray::from(key));
        let mut want = vec![0u64; 32 * 40];
        crate_blocks(&c, 0, &mut want);
        let mut s = AesStream::at(&RngPosition {
            seed: 9,
            filled_at: 0,
            idx: 0,
        });
        let mut got = Vec::new();
        let mut n = 1;
        while got.len() + n <= want.len() {
            let mut piece = vec![0u64; n];
            s.fill(&mut piece);
            got.extend(piece);
            if n % 5 == 0 {
                s = AesStream::at(&s.position());
            }
            n = n % 301 + 7;
        }
        assert_eq!(got[..], want[..got.len()]);
    }
}
