//! The campaign-wide figures of a DSMC campaign, from `dsmc_species_summary` at each point's
//! last output time t_end (where the asymptotics a campaign tests live):
//!
//! - **deviation maps** (`deviation-temperature`, `deviation-msd`): for every point (rows,
//!   labelled `id: swept values`) and species (columns), the deviation of the ensemble mean
//!   from theory in standard errors, (mean - theory) / sem (the summary's
//!   `temperature_dev_sigma`, `msd_dev_sigma`), at the point's last output time, as a heatmap
//!   clamped at +-[`SIGMA_LIMIT`]. The last time rather than the largest |deviation| over the
//!   times: the largest of some fifty correlated deviations is a few sigma even where the
//!   DSMC and the theory agree, so it would flag every point; the per-point figures show the
//!   time course. With many points the map keeps the [`MAX_MAP_CELLS`] cells (at most
//!   [`MAX_MAP_ROWS`] points) with the largest |deviation|, in point order, and says so.
//! - **across-sweep figures** (`sweep-<key>-temperature-k<k>`, `sweep-<key>-msd-k<k>`): along
//!   each sweep key with at least two distinct numeric values, T_k(t_end) and <R_k^2(t_end)>
//!   against the swept value, with sem error bars and the theory as a line, one series per
//!   combination of the other keys' values (named in the legend); species 1 and, with at most
//!   four species, all of them, else species 1 and the last. Keys with non-numeric values
//!   (`method`, ...) are never an axis, only a series; log axes where the values are positive
//!   and span more than a decade.

use std::collections::{BTreeMap, BTreeSet, HashSet};

use arrow_array::{Array, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};

use super::params::DsmcParams;
use super::tables::{DsmcSpeciesSummaryCols, DSMC_SPECIES_SUMMARY};
use crate::models::{CampaignView, Labels, SweepKey, SweepKeyCols};
use crate::plot::{Figure, Heatmap, Series};
use crate::store::parquet_io::StoreError;

type View<'a, 'b> = &'a CampaignView<'b, DsmcParams>;

/// The deviation maps' colour scale ends, in standard errors.
pub const SIGMA_LIMIT: f64 = 5.0;
/// Most cells of a deviation map, and most rows (points).
pub const MAX_MAP_CELLS: usize = 24_000;
pub const MAX_MAP_ROWS: usize = 400;

/// An ensemble mean with its standard error, the theory and (mean - theory) / sem.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measured {
    pub mean: f64,
    pub sem: f64,
    pub theory: Option<f64>,
    pub dev_sigma: Option<f64>,
}

/// One species of one point at the point's last output time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AtEnd {
    pub t: f64,
    pub temperature: Measured,
    pub msd: Option<Measured>,
}

/// point -> species -> its row at the point's last output time.
pub type Ends = BTreeMap<u32, BTreeMap<u32, AtEnd>>;

/// A swept value of a point.
#[derive(Clone, Debug, PartialEq)]
pub enum Swept {
    Num(f64),
    Text(String),
    Missing,
}

impl Swept {
    fn text(&self) -> String {
        match self {
            Swept::Num(v) => format!("{v}"),
            Swept::Text(s) => s.clone(),
            Swept::Missing => "-".into(),
        }
    }
}

/// The sweep columns (their names) and every point's values, in the columns' order.
#[derive(Clone, Debug, Default)]
pub struct Sweep {
    pub keys: Vec<String>,
    pub points: BTreeMap<u32, Vec<Swept>>,
}

/// The sweep of a campaign from its view's sweep batch (`point_id`, then one typed column per
/// key: integers and floats are numeric, booleans and strings text).
pub fn sweep_of(batch: &RecordBatch) -> Sweep {
    let schema = batch.schema();
    let Ok(SweepKeyCols { point_id: ids, .. }) = SweepKeyCols::read(batch, "sweep") else {
        return Sweep::default();
    };
    const KEY: &str = SweepKey::column("point_id");
    let cols: Vec<usize> = (0..batch.num_columns())
        .filter(|&j| schema.field(j).name() != KEY)
        .collect();
    let keys = cols
        .iter()
        .map(|&j| schema.field(j).name().clone())
        .collect();
    let mut points = BTreeMap::new();
    for i in 0..batch.num_rows() {
        let values = cols
            .iter()
            .map(|&j| {
                let a = batch.column(j).as_any();
                if batch.column(j).is_null(i) {
                    Swept::Missing
                } else if let Some(a) = a.downcast_ref::<Int64Array>() {
                    Swept::Num(a.value(i) as f64)
                } else if let Some(a) = a.downcast_ref::<Float64Array>() {
                    Swept::Num(a.value(i))
                } else if let Some(a) = a.downcast_ref::<BooleanArray>() {
                    Swept::Text(a.value(i).to_string())
                } else if let Some(a) = a.downcast_ref::<StringArray>() {
                    Swept::Text(a.value(i).to_string())
                } else {
                    Swept::Missing
                }
            })
            .collect();
        points.insert(ids.value(i), values);
    }
    Sweep { keys, points }
}

/// Every point's species at the point's last output time, from `dsmc_species_summary` (the
/// theory and deviation columns optional: absent, they are missing values).
pub fn read_ends(c: View) -> Result<Ends, StoreError> {
    // (point, species) -> the row of its latest time.
    let mut last: BTreeMap<(u32, u32), AtEnd> = BTreeMap::new();
    for f in c.data.files(DSMC_SPECIES_SUMMARY)? {
        let name = f.display().to_string();
        for b in c.data.read_file(&f, DSMC_SPECIES_SUMMARY)? {
            // The theory and deviation columns are None where the summary lacks them.
            let cols = DsmcSpeciesSummaryCols::read(&b, &name)?;
            for i in 0..cols.len() {
                let r = cols.row(i);
                let row = AtEnd {
                    t: r.t,
                    temperature: Measured {
                        mean: r.temperature_mean,
                        sem: r.temperature_sem.unwrap_or(0.0),
                        theory: r.temperature_theory,
                        dev_sigma: r.temperature_dev_sigma,
                    },
                    msd: r.msd_mean.map(|mean| Measured {
                        mean,
                        sem: r.msd_sem.unwrap_or(0.0),
                        theory: r.msd_theory,
                        dev_sigma: r.msd_dev_sigma,
                    }),
                };
                let e = last.entry((r.point_id, r.species)).or_insert(row);
                if row.t > e.t {
                    *e = row;
                }
            }
        }
    }
    let mut out: Ends = BTreeMap::new();
    for ((p, s), row) in last {
        out.entry(p).or_default().insert(s, row);
    }
    // Only the species seen at the point's last time.
    for species in out.values_mut() {
        let t_end = species.values().map(|r| r.t).fold(f64::MIN, f64::max);
        species.retain(|_, r| r.t == t_end);
    }
    Ok(out)
}

/// The campaign-wide figures: the deviation maps, then the across-sweep figures.
pub fn figures(c: View) -> Result<Vec<(String, Figure)>, StoreError> {
    let ends = read_ends(c)?;
    if ends.is_empty() {
        return Ok(Vec::new());
    }
    let labels: BTreeMap<u32, String> = c
        .points
        .iter()
        .map(|p| (p.point_id, p.label.clone()))
        .collect();
    let mut figs = deviation_maps(c.name, &labels, &ends);
    figs.extend(across_sweep(c.name, &sweep_of(&c.sweep), &ends, &c.labels));
    Ok(figs)
}

/// Which quantity a figure shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quantity {
    Temperature,
    Msd,
}

impl Quantity {
    fn of(self, r: &AtEnd) -> Option<Measured> {
        match self {
            Quantity::Temperature => Some(r.temperature),
            Quantity::Msd => r.msd,
        }
    }
    fn slug(self) -> &'static str {
        match self {
            Quantity::Temperature => "temperature",
            Quantity::Msd => "msd",
        }
    }
    fn symbol(self, k: &str) -> String {
        match self {
            Quantity::Temperature => format!("T_{k}"),
            Quantity::Msd => format!("<R_{k}^2>"),
        }
    }
}

/// The deviation maps of T_k and (where measured with theory) of the MSD, points x species.
pub fn deviation_maps(
    name: &str,
    labels: &BTreeMap<u32, String>,
    ends: &Ends,
) -> Vec<(String, Figure)> {
    let species: Vec<u32> = ends
        .values()
        .flat_map(|s| s.keys().copied())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut figs = Vec::new();
    for q in [Quantity::Temperature, Quantity::Msd] {
        let mut rows: Vec<(u32, Vec<Option<f64>>)> = ends
            .iter()
            .map(|(&p, sp)| {
                let v = species
                    .iter()
                    .map(|k| sp.get(k).and_then(|r| q.of(r)).and_then(|m| m.dev_sigma))
                    .collect();
                (p, v)
            })
            .collect();
        if rows.iter().all(|(_, v)| v.iter().all(Option::is_none)) {
            continue;
        }
        let total = rows.len();
        let cap = (MAX_MAP_CELLS / species.len().max(1)).clamp(1, MAX_MAP_ROWS);
        let mut kept = String::new();
        if total > cap {
            let worst =
                |v: &[Option<f64>]| v.iter().flatten().fold(-1.0, |a: f64, x| a.max(x.abs()));
            rows.sort_by(|a, b| worst(&b.1).total_cmp(&worst(&a.1)).then(a.0.cmp(&b.0)));
            rows.truncate(cap);
            rows.sort_by_key(|r| r.0);
            kept = format!(" ({cap} of {total} points: the largest |deviation|)");
        }
        let heat = Heatmap {
            rows: rows
                .iter()
                .map(|(p, _)| match labels.get(p).filter(|l| !l.is_empty()) {
                    Some(l) => format!("{p}: {l}"),
                    None => format!("point {p}"),
                })
                .collect(),
            cols: species.iter().map(|k| k.to_string()).collect(),
            values: rows.into_iter().map(|r| r.1).collect(),
            limit: SIGMA_LIMIT,
            scale_label: "(mean - theory) / sem at t_end".into(),
        };
        let title = format!(
            "{name}: {} - theory at the last output time, in sems{kept}",
            q.symbol("k")
        );
        figs.push((
            format!("deviation-{}", q.slug()),
            Figure::heatmap(title, "species k", "point", heat),
        ));
    }
    figs
}

/// Species shown across the sweep: all of up to 4, else the first and the last.
pub fn across_species(all: &[u32]) -> Vec<u32> {
    if all.len() <= 4 {
        all.to_vec()
    } else {
        vec![all[0], all[all.len() - 1]]
    }
}

/// One series of an across-sweep figure: the points of one combination of the other keys'
/// values, sorted by the swept value: (x, mean, sem), and the theory (x, value) where known.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// The other keys' values (`key=value` for one other key, the values joined by `, ` for
    /// more, empty for none).
    pub label: String,
    pub data: Vec<(f64, f64, f64)>,
    pub theory: Vec<(f64, f64)>,
}

/// The curves of quantity `q` of `species` along sweep key `key` (an index of `sweep.keys`),
/// or `None` when the key is not numeric at every point with data, or has fewer than two
/// distinct values there.
pub fn curves(
    sweep: &Sweep,
    key: usize,
    ends: &Ends,
    species: u32,
    q: Quantity,
) -> Option<Vec<Curve>> {
    let rows: Vec<(&Vec<Swept>, Measured)> = ends
        .iter()
        .filter_map(|(p, sp)| {
            let values = sweep.points.get(p)?;
            let m = sp.get(&species).and_then(|r| q.of(r))?;
            Some((values, m))
        })
        .collect();
    let mut xs = Vec::new();
    for (values, _) in &rows {
        match values.get(key)? {
            Swept::Num(x) if x.is_finite() => xs.push(*x),
            Swept::Missing => {}
            _ => return None,
        }
    }
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    if xs.len() < 2 {
        return None;
    }
    let others: Vec<usize> = (0..sweep.keys.len()).filter(|&j| j != key).collect();
    let mut out: Vec<Curve> = Vec::new();
    for (values, m) in rows {
        let Some(Swept::Num(x)) = values.get(key) else {
            continue;
        };
        let label = match others.as_slice() {
            [] => String::new(),
            [j] => format!("{}={}", sweep.keys[*j], values[*j].text()),
            js => js
                .iter()
                .map(|&j| values[j].text())
                .collect::<Vec<_>>()
                .join(", "),
        };
        let i = match out.iter().position(|c| c.label == label) {
            Some(i) => i,
            None => {
                out.push(Curve {
                    label,
                    data: Vec::new(),
                    theory: Vec::new(),
                });
                out.len() - 1
            }
        };
        out[i].data.push((*x, m.mean, m.sem));
        if let Some(th) = m.theory {
            out[i].theory.push((*x, th));
        }
    }
    for c in &mut out {
        c.data.sort_by(|a, b| a.0.total_cmp(&b.0));
        c.theory.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    Some(out)
}

/// Whether values are all positive and span more than a decade (then a log axis).
fn spans_decades(v: impl Iterator<Item = f64> + Clone) -> bool {
    let (lo, hi) = v.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
    lo > 0.0 && hi > 10.0 * lo
}

/// The physics name of a sweep key (its column name, `species_list_1_mass`, or its path,
/// `species.list.1.mass`) on a figure's axis: `m_2` (list index 1 is species 2), `sigma_2`,
/// `N_2`, `ε` (the restitution coefficient, as in the spec), `T(0)`, `V`, `N`, `n`, `θ`; any
/// other key as it is.
pub fn physics_name(key: &str) -> String {
    let k = key.replace('.', "_");
    if let Some(rest) = k.strip_prefix("species_list_") {
        if let Some((i, what)) = rest.split_once('_') {
            if let Ok(i) = i.parse::<u32>() {
                let sym = match what {
                    "mass" => Some("m"),
                    "diameter" => Some("σ"),
                    "count" => Some("N"),
                    "temperature" => Some("T"),
                    _ => None,
                };
                if let Some(sym) = sym {
                    return format!("{sym}_{}", i + 1);
                }
            }
        }
    }
    match k.as_str() {
        "restitution_constant" | "restitution" => "ε",
        "initial_temperature" => "T(0)",
        "volume" => "V",
        "n_particles" => "N",
        "density" => "n",
        "species_power_law_theta" => "θ",
        _ => key,
    }
    .to_string()
}

/// The across-sweep figures of every numeric sweep key.
///
/// The manifest's `labels` (of a sweep key, `temperature` or `msd`) name the axes, legends
/// and titles in place of the physics names.
pub fn across_sweep(
    name: &str,
    sweep: &Sweep,
    ends: &Ends,
    labels: &Labels,
) -> Vec<(String, Figure)> {
    let axis_name = |key: &str| {
        labels
            .given(key)
            .map(str::to_string)
            .unwrap_or_else(|| physics_name(key))
    };
    // The curves' legends (`key=value`) by the names on the figure; the figures' ids by the
    // sweep's columns.
    let named = Sweep {
        keys: sweep.keys.iter().map(|k| axis_name(k)).collect(),
        points: sweep.points.clone(),
    };
    let all: Vec<u32> = ends
        .values()
        .flat_map(|s| s.keys().copied())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let shown = across_species(&all);
    let mut figs = Vec::new();
    for (j, key) in sweep.keys.iter().enumerate() {
        let others: Vec<String> = sweep
            .keys
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != j)
            .map(|(_, k)| axis_name(k))
            .collect();
        for &k in &shown {
            for q in [Quantity::Temperature, Quantity::Msd] {
                let Some(curves) = curves(&named, j, ends, k, q) else {
                    continue;
                };
                if curves.iter().all(|c| c.data.is_empty()) {
                    continue;
                }
                // Theory lines identical for every series (the theory knows no `method`):
                // one reference line.
                let shared = curves.len() > 1
                    && curves.iter().all(|c| c.theory == curves[0].theory)
                    && !curves[0].theory.is_empty();
                let line = |label: String, th: &[(f64, f64)]| Series {
                    label,
                    points: th.iter().map(|&(x, y)| (x, y, 0.0)).collect(),
                    line: true,
                };
                let mut series = Vec::new();
                for c in &curves {
                    // A series' own theory line follows it in its colour: "theory" names it
                    // (the legend column cuts long labels).
                    let (data, theory) = if c.label.is_empty() {
                        ("DSMC".to_string(), "theory".to_string())
                    } else {
                        (c.label.clone(), "theory".to_string())
                    };
                    series.push(Series {
                        label: data,
                        points: c.data.clone(),
                        line: false,
                    });
                    if !c.theory.is_empty() && !shared {
                        series.push(line(theory, &c.theory));
                    }
                }
                let references = shared.then_some(series.len());
                if shared {
                    series.push(line("theory".into(), &curves[0].theory));
                }
                let xs = curves.iter().flat_map(|c| c.data.iter().map(|d| d.0));
                let ys = curves.iter().flat_map(|c| {
                    c.data
                        .iter()
                        .map(|d| d.1)
                        .chain(c.theory.iter().map(|d| d.1))
                });
                let by = if others.len() > 1 {
                    format!(" (series: {})", others.join(", "))
                } else {
                    String::new()
                };
                let sym = q.symbol(&k.to_string());
                let axis = axis_name(key);
                let (column, what) = match q {
                    Quantity::Temperature => ("temperature", "temperature"),
                    Quantity::Msd => ("msd", "MSD"),
                };
                let what = labels.given(column).unwrap_or(what);
                let mut fig = Figure::new(
                    format!("{name}: {sym} at t_end vs {axis}{by}"),
                    &axis,
                    &format!("{what} {sym}(t_end)"),
                    series,
                );
                fig.log_x = spans_decades(xs);
                fig.log_y = spans_decades(ys);
                fig.references_from = references;
                figs.push((format!("sweep-{key}-{}-k{k}", q.slug()), fig));
            }
        }
    }
    figs
}

/// `names` made safe as file names and HTML ids (ASCII letters, digits, `-` and `_`; anything
/// else becomes `-`) and unique (a repeated name gets `-2`, `-3`, ...), in place.
pub fn safe_unique_names(names: &mut [String]) {
    let mut seen = HashSet::new();
    for n in names.iter_mut() {
        let mut base: String = n
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '-'
                }
            })
            .collect();
        if base.is_empty() {
            base = "figure".into();
        }
        let mut name = base.clone();
        let mut i = 2;
        while !seen.insert(name.clone()) {
            name = format!("{base}-{i}");
            i += 1;
        }
        *n = name;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(mean: f64, theory: f64) -> Measured {
        Measured {
            mean,
            sem: 0.1,
            theory: Some(theory),
            dev_sigma: Some((mean - theory) / 0.1),
        }
    }

    /// 2 x 3 points: restitution (numeric) x method (text), two species.
    fn synthetic() -> (Sweep, Ends) {
        let mut sweep = Sweep {
            keys: vec!["method".into(), "restitution_constant".into()],
            points: BTreeMap::new(),
        };
        let mut ends: Ends = BTreeMap::new();
        let mut p = 0;
        for method in ["low_rank", "bird"] {
            for eps in [0.9, 0.5, 0.7] {
                sweep
                    .points
                    .insert(p, vec![Swept::Text(method.into()), Swept::Num(eps)]);
                let mut sp = BTreeMap::new();
                for k in [1u32, 2] {
                    sp.insert(
                        k,
                        AtEnd {
                            t: 100.0,
                            temperature: m(eps * k as f64 + p as f64 * 0.01, eps * k as f64),
                            msd: (k == 1).then(|| m(10.0 * eps, 10.0 * eps)),
                        },
                    );
                }
                ends.insert(p, sp);
                p += 1;
            }
        }
        (sweep, ends)
    }

    /// Along the numeric key: one curve per method, its x the sorted restitutions, each y
    /// that point's mean, the theory beside it; the text key is no axis.
    #[test]
    fn across_sweep_curves_group_by_the_other_keys() {
        let (sweep, ends) = synthetic();
        let c = curves(&sweep, 1, &ends, 2, Quantity::Temperature).expect("numeric key");
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].label, "method=low_rank");
        assert_eq!(c[1].label, "method=bird");
        let xs: Vec<f64> = c[1].data.iter().map(|d| d.0).collect();
        assert_eq!(xs, vec![0.5, 0.7, 0.9]);
        // bird, eps = 0.5 is point 4: mean 2 * 0.5 + 0.04.
        assert!((c[1].data[0].1 - 1.04).abs() < 1e-12, "{:?}", c[1].data);
        assert_eq!(c[1].theory, vec![(0.5, 1.0), (0.7, 1.4), (0.9, 1.8)]);
        assert!(curves(&sweep, 0, &ends, 1, Quantity::Temperature).is_none());
        // No MSD of species 2: no curve data at all.
        let msd = curves(&sweep, 1, &ends, 2, Quantity::Msd).unwrap_or_default();
        assert!(msd.iter().all(|c| c.data.is_empty()));
        // One distinct value: not an axis.
        let mut one = sweep.clone();
        for v in one.points.values_mut() {
            v[1] = Swept::Num(0.5);
        }
        assert!(curves(&one, 1, &ends, 1, Quantity::Temperature).is_none());
    }

    /// The figures: per shown species a temperature figure (and an MSD one for species 1),
    /// data then theory per method, names safe and distinct.
    /// Sweep keys on axes by their physics names (species list index 1 is species 2).
    #[test]
    fn sweep_keys_get_physics_names() {
        assert_eq!(physics_name("species_list_1_mass"), "m_2");
        assert_eq!(physics_name("species.list.0.diameter"), "σ_1");
        assert_eq!(physics_name("species.list.2.count"), "N_3");
        assert_eq!(physics_name("restitution_constant"), "ε");
        assert_eq!(physics_name("n_particles"), "N");
        assert_eq!(physics_name("method"), "method");
        assert_eq!(physics_name("species_list_x_mass"), "species_list_x_mass");
    }

    #[test]
    fn across_sweep_names_from_the_labels() {
        let (sweep, ends) = synthetic();
        let plain = across_sweep("c", &sweep, &ends, &Labels::default());
        assert_eq!(plain[0].1.x_label, "ε");
        assert!(plain[0].1.title.contains("vs ε"), "{}", plain[0].1.title);
        let given = [
            ("restitution.constant".to_string(), "alpha".to_string()),
            ("method".to_string(), "scheme".to_string()),
            (
                "temperature".to_string(),
                "granular temperature".to_string(),
            ),
        ]
        .into();
        let figs = across_sweep("c", &sweep, &ends, &Labels::new(given, |_| None));
        let f = &figs[0].1;
        assert_eq!(figs[0].0, "sweep-restitution_constant-temperature-k1");
        assert_eq!(f.x_label, "alpha");
        assert!(f.title.contains("vs alpha"), "{}", f.title);
        assert!(
            f.y_label.starts_with("granular temperature "),
            "{}",
            f.y_label
        );
        assert_eq!(f.series[0].label, "scheme=low_rank");
    }

    #[test]
    fn across_sweep_figures_and_names() {
        let (sweep, ends) = synthetic();
        let figs = across_sweep("c", &sweep, &ends, &Labels::default());
        let mut names: Vec<String> = figs.iter().map(|f| f.0.clone()).collect();
        assert_eq!(
            names,
            [
                "sweep-restitution_constant-temperature-k1",
                "sweep-restitution_constant-msd-k1",
                "sweep-restitution_constant-temperature-k2",
            ]
        );
        let labels =
            |f: &Figure| -> Vec<String> { f.series.iter().map(|s| s.label.clone()).collect() };
        // The same theory for both methods: one reference line.
        assert_eq!(
            labels(&figs[0].1),
            ["method=low_rank", "method=bird", "theory"]
        );
        assert_eq!(figs[0].1.references_from, Some(2));
        assert!(!figs[0].1.log_x && !figs[0].1.log_y);
        // Another theory per method: a line after each series.
        let mut ends2 = ends.clone();
        ends2
            .get_mut(&4)
            .unwrap()
            .get_mut(&1)
            .unwrap()
            .temperature
            .theory = Some(7.0);
        let figs2 = across_sweep("c", &sweep, &ends2, &Labels::default());
        assert_eq!(
            labels(&figs2[0].1),
            ["method=low_rank", "theory", "method=bird", "theory"]
        );
        assert_eq!(figs2[0].1.references_from, None);
        assert!(figs2[0].1.series[1].line && !figs2[0].1.series[2].line);
        // Values over more than a decade: log axes.
        let mut wide = sweep.clone();
        for (p, v) in wide.points.iter_mut() {
            v[1] = Swept::Num(10f64.powi(*p as i32 % 3));
        }
        let figs3 = across_sweep("c", &wide, &ends, &Labels::default());
        assert!(figs3[0].1.log_x, "x over two decades");
        assert!(!figs3[0].1.log_y);
        names.push("sweep-restitution_constant-msd-k1".into());
        names.push("a/b c.d".into());
        safe_unique_names(&mut names);
        assert_eq!(names[3], "sweep-restitution_constant-msd-k1-2");
        assert_eq!(names[4], "a-b-c-d");
        assert_eq!(across_species(&[1, 2, 3, 4]), vec![1, 2, 3, 4]);
        assert_eq!(across_species(&[1, 2, 3, 4, 5]), vec![1, 5]);
    }

    /// The maps: points x species of T (and x species of the MSD, missing where not
    /// measured), rows labelled by the swept values; capped rows keep the worst points.
    #[test]
    fn deviation_maps_hold_points_by_species() {
        let (_, ends) = synthetic();
        let labels: BTreeMap<u32, String> = (0..6).map(|p| (p, format!("x={p}"))).collect();
        let figs = deviation_maps("c", &labels, &ends);
        assert_eq!(figs.len(), 2);
        assert_eq!(figs[0].0, "deviation-temperature");
        let h = figs[0].1.heatmap.as_ref().expect("a heatmap");
        assert_eq!(h.rows.len(), 6);
        assert_eq!(h.rows[3], "3: x=3");
        assert_eq!(h.cols, vec!["1", "2"]);
        assert!((h.values[3][1].unwrap() - 0.3).abs() < 1e-9);
        let msd = figs[1].1.heatmap.as_ref().unwrap();
        assert_eq!(msd.values[0], vec![Some(0.0), None]);
        assert!(figs[0].1.title.contains("last output time"));

        // Many points: the worst MAX_MAP_ROWS, in point order.
        let mut many: Ends = BTreeMap::new();
        for p in 0..(MAX_MAP_ROWS as u32 + 50) {
            let dev = if p % 10 == 0 { 9.0 } else { 0.1 };
            let mut sp = BTreeMap::new();
            sp.insert(
                1,
                AtEnd {
                    t: 1.0,
                    temperature: Measured {
                        dev_sigma: Some(dev),
                        ..Default::default()
                    },
                    msd: None,
                },
            );
            many.insert(p, sp);
        }
        let figs = deviation_maps("c", &BTreeMap::new(), &many);
        assert_eq!(figs.len(), 1);
        let h = figs[0].1.heatmap.as_ref().unwrap();
        assert_eq!(h.rows.len(), MAX_MAP_ROWS);
        assert!(h.rows.contains(&format!("point {}", MAX_MAP_ROWS + 40)));
        assert!(h.rows.windows(2).all(|w| {
            let n = |s: &str| s[6..].parse::<u32>().unwrap();
            n(&w[0]) < n(&w[1])
        }));
        assert!(figs[0].1.title.contains("of 450 points"));
    }
}
