//! Nanoseconds per standard normal on slices of 1e4 normals (the normals of one 2D RFM step of
//! N = 5000): stream version 1's `rfm::noise::fill_normals_with` (one 64-bit word per normal,
//! the words included) against `rng::normal` (two normals per word: `normal_candidates`, then
//! `finish_slow` for the listed slots) on counter-addressed words from
//! `rng::stream::fill_counter` (one ChaCha8 stream per step), words included and excluded,
//! and the whole version-2 kick of a step (`rfm::noise::Kicks::kick_counter`).
//! Run: `cargo run --release --example bench_normals [calls]`; the best of 5 rounds is shown.

use std::hint::black_box;
use std::time::Instant;

use granular::rfm::noise::fill_normals_with;
use granular::rng::normal::{finish_slow, normal_candidates};
use granular::rng::stream::{fill_counter, key_of, WordStream};
use granular::rng::RunRng;

const N: usize = 10_000;

fn best(label: &str, calls: usize, mut f: impl FnMut(usize)) {
    let mut t = f64::INFINITY;
    for round in 0..5 {
        let t0 = Instant::now();
        for c in 0..calls {
            f(round * calls + c);
        }
        t = t.min(t0.elapsed().as_secs_f64());
    }
    println!(
        "{label:<58} {:6.3} ns per normal",
        t * 1e9 / (calls * N) as f64
    );
}

fn main() {
    let calls: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("calls: a number"))
        .unwrap_or(2000);
    let mut out = vec![0.0; N];
    let mut words = vec![0u64; N];
    let mut rejected = Vec::new();
    let mut slow = Vec::new();
    let key = key_of(42);

    let mut rng = WordStream::from_rng(&RunRng::new(42));
    best(
        "v1 words only: WordStream::fill, 1 word per normal",
        calls,
        |_| {
            rng.fill(&mut words);
            black_box(&words);
        },
    );
    let mut rng = WordStream::from_rng(&RunRng::new(42));
    best(
        "v1 fill_normals_with (64-bit ziggurat, words included)",
        calls,
        |_| {
            fill_normals_with(&mut rng, &mut out, &mut words, &mut rejected);
            black_box(&out);
        },
    );

    let mut half = vec![0u64; N / 2];
    best(
        "v2 words only: fill_counter, 1 word per 2 normals",
        calls,
        |s| {
            fill_counter(&key, s as u64, 0, &mut half);
            black_box(&half);
        },
    );
    // The slow path's continuation: a stream of its own (as the V2 noise's per-slot one).
    let mut more = WordStream::from_rng(&RunRng::new(7));
    best(
        "v2 fill_counter + normal_candidates + finish_slow",
        calls,
        |s| {
            fill_counter(&key, s as u64, 0, &mut half);
            normal_candidates(&half, &mut out, &mut slow);
            for &j in &slow {
                let j = j as usize;
                out[j] = finish_slow((half[j / 2] >> (32 * (j % 2))) as u32, &mut || more.u64());
            }
            black_box(&out);
        },
    );

    // Words excluded: 8 different sets of words (320 KB, so that the slow slots differ from
    // call to call), generated beforehand.
    let sets: Vec<Vec<u64>> = (0..8)
        .map(|s| {
            let mut w = vec![0u64; N / 2];
            fill_counter(&key, 1000 + s, 0, &mut w);
            w
        })
        .collect();
    best(
        "v2 normal_candidates + finish_slow (words excluded)",
        calls,
        |c| {
            let w = &sets[c % sets.len()];
            normal_candidates(w, &mut out, &mut slow);
            for &j in &slow {
                let j = j as usize;
                out[j] = finish_slow((w[j / 2] >> (32 * (j % 2))) as u32, &mut || more.u64());
            }
            black_box(&out);
        },
    );
    // The whole version-2 kick of one step (N = 5000 2D particles: 1e4 normals): words,
    // normals, slow slots and kicks in one fused pass per chunk, on one thread.
    let mut kicks = granular::rfm::noise::Kicks::new(1e-8, 1.0, 1e-6);
    kicks.set_seed(42);
    let mut v = vec![[0.0f64; 2]; N / 2];
    best(
        "v2 Kicks::kick_counter, 2D N 5000 (words + normals + kicks)",
        calls,
        |s| {
            black_box(kicks.kick_counter(s as u64, &mut v, false));
        },
    );
    best("v2 normal_candidates alone (words excluded)", calls, |c| {
        normal_candidates(&sets[c % sets.len()], &mut out, &mut slow);
        black_box(&out);
    });
}
