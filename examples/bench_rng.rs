//! The hardware floors of the engines' hot loops, as a small table (a few seconds in all).
//!
//! (a) Random words: 64-bit words per second of the run's ChaCha8 stream, served in bulk
//!     (`WordStream::fill`), one at a time (`RunRng::u64`), counter-addressed (`fill_counter`,
//!     the RFM noise of stream version 2), and `rand_chacha`'s `ChaCha8Rng::fill_bytes` (the
//!     same words) for reference; then AES-128 in counter mode (the DSMC words of stream
//!     version 3: `AesStream::fill`, VAES where the CPU has it, and `RunRng::u64`).
//! (b) Standard normals per second of `rfm::noise::fill_normals_with` (ziggurat on the bulk
//!     stream). The RFM MD draws 2 normals per particle-step in 2D (1 in 1D), so half of
//!     this rate is the MD's floor in particle-steps/s from the noise alone.
//! (c) Pointer chase: ns per dependent load through a random cyclic permutation (Sattolo) of
//!     16-byte and 24-byte records, at 2000, 27 000, 1e6 and 1e7 records: the latency floor
//!     of one particle access when nothing else can run (the cache level the size falls in).
//! (d) Random gather: ns per independent random load at the same sizes (the loads overlap):
//!     the throughput floor of particle accesses. DSMC low-rank makes ~2 random velocity
//!     reads per trial on N ~ 1e6 (plus ~2-3 random words), so 1 / (2 x this) bounds its
//!     trials/s; collisions/s is that times the acceptance rate.
//!
//! Run: `cargo run --release --example bench_rng`. The machine is shared: each figure is
//! the median of 5 repetitions.

use std::hint::black_box;
use std::time::Instant;

use granular::rfm::noise::fill_normals_with;
use granular::rng::aes::AesStream;
use granular::rng::stream::{fill_counter, key_of, WordStream};
use granular::rng::{Generator, RunRng};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Median seconds per item of `f`, which does `items` items per call.
fn per_item(items: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut reps = 1;
    loop {
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        if t.elapsed().as_secs_f64() > 0.02 {
            break;
        }
        reps *= 2;
    }
    let mut v: Vec<f64> = (0..5)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                f();
            }
            t.elapsed().as_secs_f64() / (reps * items) as f64
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[2]
}

fn row(what: &str, s: f64, unit: &str) {
    println!("{what:<44} {:>10.3e} {unit}/s {:>8.2} ns", 1.0 / s, s * 1e9);
}

/// A random cyclic permutation of 0..n (Sattolo's algorithm): one cycle through all.
fn sattolo(n: usize, rng: &mut RunRng) -> Vec<u32> {
    let mut p: Vec<u32> = (0..n as u32).collect();
    for i in (1..n).rev() {
        let j = rng.below(i);
        p.swap(i, j);
    }
    p
}

fn memory<const W: usize>(n: usize, rng: &mut RunRng) -> (f64, f64) {
    let perm = sattolo(n, rng);
    let mut rec = vec![[0u64; W]; n];
    for (i, r) in rec.iter_mut().enumerate() {
        r[0] = perm[i] as u64;
        r[W - 1] ^= i as u64;
    }
    drop(perm);
    // (c) dependent loads: each index comes from the previous record (fewer where each is
    // a miss to memory).
    let steps = if n >= 1_000_000 { 1 << 16 } else { 1 << 20 };
    let chase = per_item(steps, || {
        let mut i = 0usize;
        for _ in 0..steps {
            i = unsafe { rec.get_unchecked(i) }[0] as usize;
        }
        black_box(i);
    });
    // (d) independent loads at precomputed random indices.
    let loads = 1 << 20;
    let idx: Vec<u32> = (0..loads).map(|_| rng.below(n) as u32).collect();
    let gather = per_item(loads, || {
        let mut s = 0u64;
        for &i in &idx {
            s = s.wrapping_add(unsafe { rec.get_unchecked(i as usize) }[W - 1]);
        }
        black_box(s);
    });
    (chase, gather)
}

fn main() {
    println!("(a) random 64-bit words");
    let mut buf = vec![0u64; 4096];
    let mut ws = WordStream::from_rng(&RunRng::new(1));
    row(
        "WordStream::fill (bulk, 4096 words)",
        per_item(buf.len(), || ws.fill(black_box(&mut buf))),
        "words",
    );
    let mut rr = RunRng::new(1);
    row(
        "RunRng::u64 (one at a time)",
        per_item(4096, || {
            let mut s = 0u64;
            for _ in 0..4096 {
                s ^= rr.u64();
            }
            black_box(s);
        }),
        "words",
    );
    let key = key_of(1);
    let mut block = 0u64;
    row(
        "fill_counter (4096 words)",
        per_item(buf.len(), || {
            fill_counter(&key, 7, block, black_box(&mut buf));
            block += 512;
        }),
        "words",
    );
    let mut aes = AesStream::at(&RunRng::new(1).position());
    row(
        "AES-128-CTR AesStream::fill (4096 words)",
        per_item(buf.len(), || aes.fill(black_box(&mut buf))),
        "words",
    );
    let mut ra = RunRng::with_generator(1, Generator::Aes128Ctr);
    row(
        "AES-128-CTR RunRng::u64 (one at a time)",
        per_item(4096, || {
            let mut s = 0u64;
            for _ in 0..4096 {
                s ^= ra.u64();
            }
            black_box(s);
        }),
        "words",
    );
    let mut cc = ChaCha8Rng::seed_from_u64(1);
    let mut bytes = vec![0u8; 8 * 4096];
    row(
        "rand_chacha ChaCha8Rng::fill_bytes (ref.)",
        per_item(4096, || cc.fill_bytes(black_box(&mut bytes))),
        "words",
    );

    println!("(b) standard normals (MD 2D: 2 per particle-step)");
    let mut ws = WordStream::from_rng(&RunRng::new(2));
    let (mut out, mut words, mut rej) = (vec![0.0; 4000], Vec::new(), Vec::new());
    row(
        "fill_normals_with (4000 = N 2000, 2D)",
        per_item(out.len(), || {
            fill_normals_with(&mut ws, black_box(&mut out), &mut words, &mut rej)
        }),
        "normals",
    );

    println!("(c) pointer chase (dependent loads) / (d) random gather (independent loads)");
    let mut rng = RunRng::new(3);
    for n in [2000usize, 27_000, 1_000_000, 10_000_000] {
        let (c16, g16) = memory::<2>(n, &mut rng);
        row(&format!("chase  16-byte records, n = {n}"), c16, "loads");
        row(&format!("gather 16-byte records, n = {n}"), g16, "loads");
        let (c24, g24) = memory::<3>(n, &mut rng);
        row(&format!("chase  24-byte records, n = {n}"), c24, "loads");
        row(&format!("gather 24-byte records, n = {n}"), g24, "loads");
    }
}
