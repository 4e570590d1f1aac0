//! The cost of the table checksums: SHA-256 throughput of `store::checksum` as tables are
//! written (`HashingWriter` in front of a file) and verified (`sum_file`), against the plain
//! write, on a 512 MiB file in the system's temporary directory.
//!
//! `cargo run --release --example bench_checksum [MiB]`

use std::io::Write;
use std::time::Instant;

use granular::store::checksum::{sum_file, HashingWriter};

fn main() {
    let mib: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(512);
    let dir = tempfile::tempdir().expect("temp dir");
    let chunk: Vec<u8> = (0..1 << 20)
        .map(|i: u32| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let write = |path: &std::path::Path, hash: bool| {
        let t = Instant::now();
        let f = std::fs::File::create(path).expect("create");
        if hash {
            let mut w = HashingWriter::new(f);
            for _ in 0..mib {
                w.write_all(&chunk).expect("write");
            }
            let (f, _, _) = w.finish();
            f.sync_all().expect("sync");
        } else {
            let mut f = f;
            for _ in 0..mib {
                f.write_all(&chunk).expect("write");
            }
            f.sync_all().expect("sync");
        }
        t.elapsed().as_secs_f64()
    };
    let (a, b) = (dir.path().join("plain"), dir.path().join("hashed"));
    let mut plain = f64::MAX;
    let mut hashed = f64::MAX;
    for _ in 0..3 {
        plain = plain.min(write(&a, false));
        hashed = hashed.min(write(&b, true));
    }
    let t = Instant::now();
    let (bytes, _) = sum_file(&b).expect("sum");
    let verify = t.elapsed().as_secs_f64();
    let gb = bytes as f64 / 1e9;
    println!("{mib} MiB, best of 3 writes (fsynced):");
    println!("  plain write        {plain:.3} s ({:.2} GB/s)", gb / plain);
    println!(
        "  write + SHA-256    {hashed:.3} s ({:.2} GB/s), +{:.1} %",
        gb / hashed,
        (hashed / plain - 1.0) * 100.0
    );
    println!(
        "  verify (read + SHA-256, file in page cache) {verify:.3} s ({:.2} GB/s)",
        gb / verify
    );
}
