//! The optional per-row values of `dsmc_species`: one scalar per output time and species,
//! computed from the species' velocities when its observable is on (a2 of
//! `velocity_distribution`, ...).
//!
//! To add one: a variant of [`RowValue`] (listed in [`RowValue::ALL`], in column order) with
//! its column name in [`RowValue::column`] and its computation in [`RowValue::compute`]; its
//! observable maps to it in `models::dsmc::params` (`DsmcObservable::row_value`) and its
//! column goes into `models::dsmc::tables::species_batch`. Everything else follows: the rows
//! carry it ([`RowValues`] in `SpeciesRow::values`), checkpoints save it (one [`RowValuesExtra`] after the state),
//! the memory estimate counts it (the size of a `SpeciesRow`) and the model's valued columns
//! list it. A value must draw no random numbers and must not modify the state (determinism
//! rules 4 and 6 of ARCHITECTURE.md).

use serde::{Deserialize, Serialize};

use super::vdist;
use crate::physics::SimError;

/// One species at one output time: what a per-row value is computed from.
pub struct SpeciesSample<'a> {
    pub t: f64,
    pub mass: f64,
    pub diameter: f64,
    pub count: u64,
    /// The species' velocities (lab frame).
    pub vel: &'a [[f64; 3]],
    /// sum |v|^2 over `vel`: the very bits of T_k = m_k v2 / (3 N_k).
    pub v2: f64,
}

/// A per-row value of `dsmc_species`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RowValue {
    /// The Sonine coefficient 3 <v^4>_k / (5 <v^2>_k^2) - 1 (observable
    /// `velocity_distribution`; lab-frame velocities, as T_k).
    A2,
    /// Tests only: the mean x velocity of the species (saved in the generic section, which no
    /// value of the library needs yet).
    #[cfg(test)]
    Probe,
}

impl RowValue {
    /// Every per-row value, in the order of their columns and of their checkpoint section.
    pub const ALL: &'static [RowValue] = &[
        RowValue::A2,
        #[cfg(test)]
        RowValue::Probe,
    ];

    /// The column of `dsmc_species` it fills (nullable: null where it is not recorded).
    pub fn column(self) -> &'static str {
        match self {
            RowValue::A2 => "a2",
            #[cfg(test)]
            RowValue::Probe => "probe",
        }
    }

    /// Its value for one species at one output time (None where it is not defined).
    pub fn compute(self, s: &SpeciesSample) -> Option<f64> {
        match self {
            RowValue::A2 => {
                // v4 in the same order as v2 (the bits of the single pass it once shared).
                let mut v4 = 0.0;
                for v in s.vel {
                    let w = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                    v4 += w * w;
                }
                vdist::sonine_a2(s.count, s.v2, v4)
            }
            #[cfg(test)]
            RowValue::Probe => Some(s.vel.iter().map(|v| v[0]).sum::<f64>() / s.count as f64),
        }
    }

    /// Whether a checkpoint keeps it in the generic [`RowValuesExtra`]: all but a2, which
    /// keeps its place in the [`super::VdistExtra`] (the layout of granular before this
    /// section, so that older checkpoints load).
    pub fn generic(self) -> bool {
        self != RowValue::A2
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// How many per-row values there are.
pub const COUNT: usize = RowValue::ALL.len();
const _: () = assert!(COUNT <= 64, "RowValueSet is a 64-bit mask");

/// The per-row values of one row: None where not recorded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowValues([Option<f64>; COUNT]);

impl Default for RowValues {
    fn default() -> Self {
        RowValues([None; COUNT])
    }
}

impl RowValues {
    pub fn get(&self, v: RowValue) -> Option<f64> {
        self.0[v.index()]
    }

    pub fn set(&mut self, v: RowValue, x: Option<f64>) {
        self.0[v.index()] = x;
    }

    /// The values of `on` for one species sample (the others None).
    pub fn compute(on: RowValueSet, s: &SpeciesSample) -> RowValues {
        let mut r = RowValues::default();
        for v in on.iter() {
            r.set(v, v.compute(s));
        }
        r
    }
}

/// A set of per-row values (those a run records).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct RowValueSet(u64);

impl RowValueSet {
    pub fn contains(&self, v: RowValue) -> bool {
        self.0 & (1 << v.index()) != 0
    }

    pub fn insert(&mut self, v: RowValue) {
        self.0 |= 1 << v.index();
    }

    pub fn is_empty(&self) -> bool {
        self.0 == 0
    }

    /// The members in [`RowValue::ALL`] order.
    pub fn iter(self) -> impl Iterator<Item = RowValue> {
        RowValue::ALL
            .iter()
            .copied()
            .filter(move |v| self.contains(*v))
    }

    /// The members a checkpoint keeps in the generic section, in order.
    fn generic(self) -> impl Iterator<Item = RowValue> {
        self.iter().filter(|v| v.generic())
    }
}

impl FromIterator<RowValue> for RowValueSet {
    fn from_iter<I: IntoIterator<Item = RowValue>>(iter: I) -> Self {
        let mut s = RowValueSet::default();
        for v in iter {
            s.insert(v);
        }
        s
    }
}

/// What the generic per-row values add to a checkpoint, after the state (and the
/// [`super::VdistExtra`] if any), only when a run records one: per value (in
/// [`RowValue::ALL`] order) its column name and its value in every recorded row.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct RowValuesExtra {
    pub columns: Vec<(String, Vec<Option<f64>>)>,
}

/// Append the generic section of `on` for `rows` (the values of each by `values`; nothing
/// when `on` has no generic value). Generic over the row type so that this file imports
/// nothing of `dsmc` but `vdist`.
pub(super) fn save<R>(
    on: RowValueSet,
    rows: &[R],
    values: impl Fn(&R) -> &RowValues,
    bytes: &mut Vec<u8>,
) {
    if on.generic().next().is_none() {
        return;
    }
    let extra = RowValuesExtra {
        columns: on
            .generic()
            .map(|v| {
                (
                    v.column().to_string(),
                    rows.iter().map(|r| values(r).get(v)).collect(),
                )
            })
            .collect(),
    };
    bytes.extend(postcard::to_stdvec(&extra).expect("per-row values serialise"));
}

/// Read the generic section of `on` from `rest` into `rows` (the values of each by `values`;
/// nothing when `on` has no generic value); what follows it.
pub(super) fn restore<'a, R>(
    on: RowValueSet,
    rows: &mut [R],
    values: impl Fn(&mut R) -> &mut RowValues,
    rest: &'a [u8],
) -> Result<&'a [u8], SimError> {
    let want: Vec<RowValue> = on.generic().collect();
    if want.is_empty() {
        return Ok(rest);
    }
    let names = || {
        want.iter()
            .map(|v| v.column())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let (extra, after): (RowValuesExtra, &[u8]) = postcard::take_from_bytes(rest).map_err(|e| {
        SimError::State(format!(
            "checkpoint has no per-row values ({}): {e}",
            names()
        ))
    })?;
    let same = extra.columns.len() == want.len()
        && extra
            .columns
            .iter()
            .zip(&want)
            .all(|((name, values), v)| name == v.column() && values.len() == rows.len());
    if !same {
        return Err(SimError::State(format!(
            "checkpoint's per-row values do not match the run's observables ({})",
            names()
        )));
    }
    for ((_, column), v) in extra.columns.into_iter().zip(want) {
        for (r, x) in rows.iter_mut().zip(column) {
            values(r).set(v, x);
        }
    }
    Ok(after)
}
