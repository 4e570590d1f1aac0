//! Ensemble summaries of a DSMC campaign over replicas: `dsmc_species_summary` (mean and
//! standard error of the mean per point, time and species, joined with `dsmc_theory`: the
//! theory values and the deviations in sigmas and relative) and `dsmc_tamsd_summary` (the
//! same per point, species and lag, with the theory (27)). Derived data: rewritten whole,
//! atomically, whenever the campaign completes. Reads the raw table in chunks of points so
//! memory stays bounded, and sums in replica order so the result is bit-identical however
//! the runs were scheduled.

use std::collections::BTreeMap;

use arrow_array::RecordBatch;

use super::params::DsmcParams;
use super::tables::*;
use crate::math::stats::{mean_sem, replica_mean_sem};
use crate::models::CampaignView;
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, DsmcParams>;

/// Rows of the raw table held at once (per chunk of points).
const CHUNK_ROWS: u64 = 4_000_000;

type Key = (u32, u64, u32); // point, t bits, species

/// Write both summaries (the TAMSD one only when it is observed).
pub fn write(c: View) -> Result<(), StoreError> {
    write_species_summary(c)?;
    let points: Vec<&DsmcParams> = c.points.iter().map(|p| p.params).collect();
    if super::observes_tamsd(&points) {
        write_tamsd_summary(c)?;
    }
    if super::observes_vdist(&points) {
        write_hist_summary(c)?;
    }
    Ok(())
}

/// Points per chunk so that a chunk holds at most `CHUNK_ROWS` raw rows.
fn points_per_chunk(c: View, rows_per_run: impl Fn(&DsmcParams) -> u64) -> u32 {
    let replicas = c.replicas as u64;
    let rows_per_point = c
        .points
        .iter()
        .map(|p| rows_per_run(p.params) * replicas)
        .max()
        .unwrap_or(1)
        .max(1);
    (CHUNK_ROWS / rows_per_point).max(1) as u32
}

/// Species of a point (1 if it has none).
fn species_count(d: &DsmcParams) -> u64 {
    d.species_counts().map_or(1, |c| c.len().max(1)) as u64
}

/// One replica's values at a (point, t, species): (replica, temperature, msd, a2).
type ReplicaValues = (u32, f64, Option<f64>, Option<f64>);

/// A histogram bin across replicas: (c_lo, c_hi, [(replica, density)]).
type HistBin = (f64, f64, Vec<(u32, f64)>);

fn write_species_summary(c: View) -> Result<(), StoreError> {
    let files = c.data.files(DSMC_SPECIES)?;
    let points_per_chunk = points_per_chunk(c, |d| {
        species_count(d) * d.output_times.resolve(d.t_end).len() as u64
    });
    // Point ids of the view (the latest manifest's points) are not contiguous: chunks of ids.
    let n_points = c.points.iter().map(|p| p.point_id + 1).max().unwrap_or(0);

    let theory = read_theory(c)?;
    let mut out: Vec<SummaryRow> = Vec::new();
    let mut p0 = 0u32;
    while p0 < n_points {
        let p1 = (p0 + points_per_chunk).min(n_points);
        // (point, t, species) -> [(replica, temperature, msd, a2)]
        let mut acc: BTreeMap<Key, Vec<ReplicaValues>> = BTreeMap::new();
        for f in &files {
            let name = f.display().to_string();
            for b in c.data.read_file(f, DSMC_SPECIES)? {
                // Tables written before the observable existed have no `a2` column (None).
                let cols = DsmcSpeciesCols::read(&b, &name)?;
                for i in 0..cols.len() {
                    let r = cols.row(i);
                    let p = r.point_id;
                    let replica = c.done.get(&r.run_id);
                    let (Some(&replica), true) = (replica, p >= p0 && p < p1) else {
                        continue;
                    };
                    acc.entry((p, r.t.to_bits(), r.species)).or_default().push((
                        replica,
                        r.temperature,
                        r.msd,
                        r.a2,
                    ));
                }
            }
        }
        // Points whose replicas are not all finished (failed ones excluded) are summarised
        // over the replicas that succeeded.
        let mut order: Vec<Key> = acc.keys().copied().collect();
        order.sort_by(|a, b| {
            (a.0, f64::from_bits(a.1), a.2)
                .partial_cmp(&(b.0, f64::from_bits(b.1), b.2))
                .expect("finite times")
        });
        for key in order {
            let mut v = acc.remove(&key).expect("key");
            v.sort_by_key(|x| x.0);
            v.dedup_by_key(|x| x.0);
            let temps: Vec<f64> = v.iter().map(|x| x.1).collect();
            let (tm, ts) = mean_sem(&temps);
            let msds: Vec<f64> = v.iter().filter_map(|x| x.2).collect();
            let (mm, ms) = if msds.len() == v.len() && !msds.is_empty() {
                let (m, s) = mean_sem(&msds);
                (Some(m), s)
            } else {
                (None, None)
            };
            let a2s: Vec<f64> = v.iter().filter_map(|x| x.3).collect();
            let (am, as_) = if a2s.len() == v.len() && !a2s.is_empty() {
                let (m, s) = mean_sem(&a2s);
                (Some(m), s)
            } else {
                (None, None)
            };
            let th = theory.get(&key).copied();
            out.push(SummaryRow {
                point: key.0,
                t: f64::from_bits(key.1),
                species: key.2,
                n: v.len() as u32,
                tm,
                ts,
                mm,
                ms,
                am,
                as_,
                t_th: th.map(|x| x.0),
                m_th: th.and_then(|x| x.1),
                ts_th: th.and_then(|x| x.2),
                a2_th: th.and_then(|x| x.3),
                ms_th: th.and_then(|x| x.4),
            });
        }
        p0 = p1;
    }
    c.write_summary(DSMC_SPECIES_SUMMARY, &species_summary(&out))
}

type TamsdKey = (u32, u32, u64); // point, species, lag bits

/// `dsmc_tamsd_summary`: mean and standard error over the finished replicas of each (point,
/// species, lag), with the theory (27) joined; in chunks of points, summed in replica order.
fn write_tamsd_summary(c: View) -> Result<(), StoreError> {
    let files = c.data.files(DSMC_TAMSD)?;
    let points_per_chunk = points_per_chunk(c, |d| match (&d.tamsd, d.wants_tamsd()) {
        (Some(tm), true) => species_count(d) * tm.lags.len() as u64,
        _ => 0,
    });
    // Point ids of the view (the latest manifest's points) are not contiguous: chunks of ids.
    let n_points = c.points.iter().map(|p| p.point_id + 1).max().unwrap_or(0);
    let theory = read_tamsd_theory(c)?;
    let mut rows: Vec<TamsdSummaryRow> = Vec::new();
    let mut p0 = 0u32;
    while p0 < n_points && !files.is_empty() {
        let p1 = (p0 + points_per_chunk).min(n_points);
        // (point, species, lag) -> [(replica, tamsd)]
        let mut acc: BTreeMap<TamsdKey, Vec<(u32, f64)>> = BTreeMap::new();
        for f in &files {
            let name = f.display().to_string();
            for b in c.data.read_file(f, DSMC_TAMSD)? {
                let cols = DsmcTamsdCols::read(&b, &name)?;
                for i in 0..cols.len() {
                    let r = cols.row(i);
                    let p = r.point_id;
                    let replica = c.done.get(&r.run_id);
                    let (Some(&replica), true) = (replica, p >= p0 && p < p1) else {
                        continue;
                    };
                    acc.entry((p, r.species, r.lag.to_bits()))
                        .or_default()
                        .push((replica, r.tamsd));
                }
            }
        }
        let mut order: Vec<TamsdKey> = acc.keys().copied().collect();
        order.sort_by(|a, b| {
            (a.0, a.1, f64::from_bits(a.2))
                .partial_cmp(&(b.0, b.1, f64::from_bits(b.2)))
                .expect("finite lags")
        });
        for key in order {
            let (n, mean, sem) = replica_mean_sem(acc.remove(&key).expect("key"));
            rows.push(TamsdSummaryRow {
                point: key.0,
                species: key.1,
                lag: f64::from_bits(key.2),
                n,
                mean,
                sem,
                theory: theory.get(&key).copied(),
            });
        }
        p0 = p1;
    }
    c.write_summary(DSMC_TAMSD_SUMMARY, &tamsd_summary(&rows))
}

/// Theory (27) by (point, species, lag bits), if the table exists.
fn read_tamsd_theory(c: View) -> Result<BTreeMap<TamsdKey, f64>, StoreError> {
    let mut out = BTreeMap::new();
    for f in c.data.files(DSMC_THEORY_TAMSD)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_THEORY_TAMSD)? {
            for r in DsmcTheoryTamsd::read_rows(&b, &name)? {
                out.insert((r.point_id, r.species, r.lag.to_bits()), r.tamsd);
            }
        }
    }
    Ok(out)
}

type HistKey = (u32, u64, u32, u32); // point, t bits, species, bin

/// `dsmc_speed_histogram_summary`: mean and standard error of the density over the finished
/// replicas of each (point, t, species, bin); in chunks of points, summed in replica order.
fn write_hist_summary(c: View) -> Result<(), StoreError> {
    let files = c.data.files(DSMC_SPEED_HISTOGRAM)?;
    let points_per_chunk = points_per_chunk(c, |d| {
        let bins = d.velocity_distribution.as_ref().map_or(60, |v| v.bins) as u64;
        species_count(d) * d.vdist_times().len() as u64 * bins
    });
    // Point ids of the view (the latest manifest's points) are not contiguous: chunks of ids.
    let n_points = c.points.iter().map(|p| p.point_id + 1).max().unwrap_or(0);
    let mut rows: Vec<HistSummaryRow> = Vec::new();
    let mut p0 = 0u32;
    while p0 < n_points && !files.is_empty() {
        let p1 = (p0 + points_per_chunk).min(n_points);
        // (point, t, species, bin) -> (c_lo, c_hi, [(replica, density)])
        let mut acc: BTreeMap<HistKey, HistBin> = BTreeMap::new();
        for f in &files {
            let name = f.display().to_string();
            for b in c.data.read_file(f, DSMC_SPEED_HISTOGRAM)? {
                let cols = DsmcSpeedHistogramCols::read(&b, &name)?;
                for i in 0..cols.len() {
                    let r = cols.row(i);
                    let p = r.point_id;
                    let replica = c.done.get(&r.run_id);
                    let (Some(&replica), true) = (replica, p >= p0 && p < p1) else {
                        continue;
                    };
                    acc.entry((p, r.t.to_bits(), r.species, r.bin))
                        .or_insert_with(|| (r.c_lo, r.c_hi, Vec::new()))
                        .2
                        .push((replica, r.density));
                }
            }
        }
        let mut order: Vec<HistKey> = acc.keys().copied().collect();
        order.sort_by(|a, b| {
            (a.0, f64::from_bits(a.1), a.2, a.3)
                .partial_cmp(&(b.0, f64::from_bits(b.1), b.2, b.3))
                .expect("finite times")
        });
        for key in order {
            let (c_lo, c_hi, v) = acc.remove(&key).expect("key");
            let (n, mean, sem) = replica_mean_sem(v);
            rows.push(HistSummaryRow {
                point: key.0,
                t: f64::from_bits(key.1),
                species: key.2,
                bin: key.3,
                c_lo,
                c_hi,
                n,
                mean,
                sem,
            });
        }
        p0 = p1;
    }
    c.write_summary(DSMC_SPEED_HISTOGRAM_SUMMARY, &hist_summary(&rows))
}

/// One row of `dsmc_speed_histogram_summary`.
struct HistSummaryRow {
    point: u32,
    t: f64,
    species: u32,
    bin: u32,
    c_lo: f64,
    c_hi: f64,
    n: u32,
    mean: f64,
    sem: Option<f64>,
}

fn hist_summary(rows: &[HistSummaryRow]) -> RecordBatch {
    let rows: Vec<DsmcSpeedHistogramSummary> = rows
        .iter()
        .map(|r| DsmcSpeedHistogramSummary {
            point_id: r.point,
            t: r.t,
            species: r.species,
            bin: r.bin,
            c_lo: r.c_lo,
            c_hi: r.c_hi,
            n_replicas: r.n,
            density_mean: r.mean,
            density_sem: r.sem,
        })
        .collect();
    DsmcSpeedHistogramSummary::batch(&rows)
}

/// One row of `dsmc_tamsd_summary`.
struct TamsdSummaryRow {
    point: u32,
    species: u32,
    lag: f64,
    n: u32,
    mean: f64,
    sem: Option<f64>,
    theory: Option<f64>,
}

fn tamsd_summary(rows: &[TamsdSummaryRow]) -> RecordBatch {
    let rows: Vec<DsmcTamsdSummary> = rows
        .iter()
        .map(|r| DsmcTamsdSummary {
            point_id: r.point,
            species: r.species,
            lag: r.lag,
            n_replicas: r.n,
            tamsd_mean: r.mean,
            tamsd_sem: r.sem,
            tamsd_theory: r.theory,
        })
        .collect();
    DsmcTamsdSummary::batch(&rows)
}

/// One row of `dsmc_species_summary` before the deviations.
struct SummaryRow {
    point: u32,
    t: f64,
    species: u32,
    n: u32,
    tm: f64,
    ts: Option<f64>,
    mm: Option<f64>,
    ms: Option<f64>,
    am: Option<f64>,
    as_: Option<f64>,
    t_th: Option<f64>,
    m_th: Option<f64>,
    /// Sonine theory (None for velocity-dependent restitution, or a theory table written
    /// before the Sonine columns existed).
    ts_th: Option<f64>,
    a2_th: Option<f64>,
    /// msd_sonine (None also where the msd is not recorded).
    ms_th: Option<f64>,
}

impl SummaryRow {
    fn temperature_dev(&self) -> (Option<f64>, Option<f64>) {
        deviations(Some(self.tm), self.ts, self.t_th)
    }
    fn msd_dev(&self) -> (Option<f64>, Option<f64>) {
        deviations(self.mm, self.ms, self.m_th)
    }
    fn temperature_sonine_dev(&self) -> (Option<f64>, Option<f64>) {
        deviations(Some(self.tm), self.ts, self.ts_th)
    }
    fn msd_sonine_dev(&self) -> (Option<f64>, Option<f64>) {
        deviations(self.mm, self.ms, self.ms_th)
    }
}

fn species_summary(rows: &[SummaryRow]) -> RecordBatch {
    let rows: Vec<DsmcSpeciesSummary> = rows
        .iter()
        .map(|r| DsmcSpeciesSummary {
            point_id: r.point,
            t: r.t,
            species: r.species,
            n_replicas: r.n,
            temperature_mean: r.tm,
            temperature_sem: r.ts,
            msd_mean: r.mm,
            msd_sem: r.ms,
            temperature_theory: r.t_th,
            msd_theory: r.m_th,
            temperature_dev_sigma: r.temperature_dev().0,
            temperature_dev_rel: r.temperature_dev().1,
            msd_dev_sigma: r.msd_dev().0,
            msd_dev_rel: r.msd_dev().1,
            temperature_sonine: r.ts_th,
            temperature_sonine_dev_sigma: r.temperature_sonine_dev().0,
            temperature_sonine_dev_rel: r.temperature_sonine_dev().1,
            msd_sonine: r.ms_th,
            msd_sonine_dev_sigma: r.msd_sonine_dev().0,
            msd_sonine_dev_rel: r.msd_sonine_dev().1,
            a2_mean: r.am,
            a2_sem: r.as_,
            a2_theory: r.a2_th,
        })
        .collect();
    DsmcSpeciesSummary::batch(&rows)
}

/// (mean - theory) / sem and (mean - theory) / theory.
fn deviations(
    mean: Option<f64>,
    sem: Option<f64>,
    theory: Option<f64>,
) -> (Option<f64>, Option<f64>) {
    match (mean, theory) {
        (Some(m), Some(t)) => (
            sem.filter(|s| *s > 0.0).map(|s| (m - t) / s),
            (t != 0.0).then(|| (m - t) / t),
        ),
        _ => (None, None),
    }
}

/// Theory values by (point, t bits, species), if the table exists.
type TheoryValues = (f64, Option<f64>, Option<f64>, Option<f64>, Option<f64>);

/// Theory values (temperature, msd, temperature_sonine, a2, msd_sonine) by (point, t bits,
/// species), if
/// the table exists. The Sonine columns are None where a theory file predates them.
fn read_theory(c: View) -> Result<BTreeMap<Key, TheoryValues>, StoreError> {
    let mut out = BTreeMap::new();
    for f in c.data.files(DSMC_THEORY)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_THEORY)? {
            // The Sonine columns and a2 are None where a theory file predates them.
            for r in DsmcTheory::read_rows(&b, &name)? {
                out.insert(
                    (r.point_id, r.t.to_bits(), r.species),
                    (
                        r.temperature,
                        r.msd,
                        r.temperature_sonine,
                        r.a2,
                        r.msd_sonine,
                    ),
                );
            }
        }
    }
    Ok(out)
}
