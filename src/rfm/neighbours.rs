//! Which pairs can touch (spec 1.6, 1.7).
//!
//! - 1D: particles cannot pass each other, so the pairs are the ring neighbours
//!   (i, i+1 mod N), with the forward gap (the last pair wraps by L). Positions are kept
//!   unwrapped and ordered, so no neighbour search is ever needed.
//! - 2D: a Verlet neighbour list of all pairs closer than `d + skin`, built from a cell list
//!   (cells of side >= d + skin, periodic; all pairs when there are fewer than 3 cells per
//!   side). Each pair stores its periodic image shift at build time, so the per-step
//!   separation is `x_i - x_j + shift` without wrapping. The simulation rebuilds the list
//!   when twice the largest displacement since the build plus a bound on the coming step's
//!   motion exceeds the skin.

/// A candidate pair with its image shift: separation `x_i - x_j + shift`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair<const D: usize> {
    pub i: u32,
    pub j: u32,
    pub shift: [f64; D],
}

/// `dx` mapped to its minimum image in a periodic interval of length `l`:
/// dx - l round(dx / l), bit for bit.
#[inline]
pub fn min_image(dx: f64, l: f64) -> f64 {
    dx - l * round_near(dx / l)
}

/// `q.round()` (halves away from zero, the sign of a zero result kept), without the libm
/// call for |q| < 1.5 (every difference of two wrapped positions); `tests::fast_rounding`.
#[inline(always)]
fn round_near(q: f64) -> f64 {
    if q >= 0.5 {
        if q < 1.5 {
            1.0
        } else {
            q.round()
        }
    } else if q <= -0.5 {
        if q > -1.5 {
            -1.0
        } else {
            q.round()
        }
    } else if q.is_nan() {
        q
    } else {
        0.0f64.copysign(q)
    }
}

/// `q.floor()`, without the libm call for q in [0, 1) (every wrapped position);
/// `tests::fast_rounding`.
#[inline(always)]
fn floor_near(q: f64) -> f64 {
    if (0.0..1.0).contains(&q) {
        0.0f64.copysign(q)
    } else {
        q.floor()
    }
}

/// Wrap into [0, l).
#[inline]
pub fn wrap(x: f64, l: f64) -> f64 {
    let y = x - l * floor_near(x / l);
    if y >= l {
        0.0
    } else {
        y
    }
}

/// The cell grid of [`NeighbourList::build`] for `n` particles in a periodic box of side `l`
/// with list radius `reach`: (cells per side, cell side), or None when the list takes all
/// pairs (fewer than 3 cells per side).
pub fn cell_grid<const D: usize>(n: usize, l: f64, reach: f64) -> Option<(usize, f64)> {
    // Cells of side >= reach, at most ~4 N of them.
    let cap = ((4 * n.max(16)) as f64).powf(1.0 / D as f64).floor() as usize;
    let nc = ((l / reach).floor() as usize).min(cap);
    (nc >= 3).then(|| (nc, l / nc as f64))
}

/// The flat index of the cell (of a [`cell_grid`] of `nc` cells of side `side` per side) that
/// holds the wrapped position `p`: the first component varies fastest.
#[inline]
pub fn cell_index<const D: usize>(p: &[f64; D], nc: usize, side: f64) -> usize {
    let c: [usize; D] = std::array::from_fn(|k| ((p[k] / side) as usize).min(nc - 1));
    c.iter().rev().fold(0, |acc, &ck| acc * nc + ck)
}

/// Verlet list built from a periodic cell grid.
#[derive(Default, Clone, Debug)]
pub struct NeighbourList<const D: usize> {
    pub pairs: Vec<Pair<D>>,
    head: Vec<u32>,
    next: Vec<u32>,
    /// [`build_by_cell`](Self::build_by_cell)'s pairs per part of the cells.
    part_pairs: Vec<Vec<Pair<D>>>,
}

const NONE: u32 = u32::MAX;

impl<const D: usize> NeighbourList<D> {
    /// Rebuild from positions `x` (wrapped into [0, l)) with list radius `reach`
    /// (pairs with |x_i - x_j| < reach under the minimum image; needs reach < l/2).
    /// Deterministic: the pair order is a function of `x` alone.
    pub fn build(&mut self, x: &[[f64; D]], l: f64, reach: f64) {
        self.pairs.clear();
        let n = x.len();
        let grid = cell_grid::<D>(n, l, reach);
        let r2 = reach * reach;
        let push = |i: usize, j: usize, pairs: &mut Vec<Pair<D>>| {
            pairs.extend(near_pair(x, l, r2, i, j));
        };
        let Some((nc, side)) = grid else {
            for i in 0..n {
                for j in i + 1..n {
                    push(i, j, &mut self.pairs);
                }
            }
            return;
        };
        let ncells = nc.pow(D as u32);
        self.head.clear();
        self.head.resize(ncells, NONE);
        self.next.clear();
        self.next.resize(n, NONE);
        // Insert in reverse so each cell's chain runs in increasing particle index.
        for i in (0..n).rev() {
            let c = cell_index(&x[i], nc, side);
            self.next[i] = self.head[c];
            self.head[c] = i as u32;
        }
        for c in 0..ncells {
            if self.head[c] == NONE {
                continue;
            }
            half_stencil::<D>(c, nc, |c2| {
                let mut i = self.head[c];
                while i != NONE {
                    // The cell itself: each pair once (j after i in the chain).
                    let mut j = if c2 == c {
                        self.next[i as usize]
                    } else {
                        self.head[c2]
                    };
                    while j != NONE {
                        push(i as usize, j as usize, &mut self.pairs);
                        j = self.next[j as usize];
                    }
                    i = self.next[i as usize];
                }
            });
        }
    }
}

impl<const D: usize> NeighbourList<D> {
    /// [`build`](Self::build) for positions stored by cell: `x` in the order of the cells of
    /// the [`cell_grid`] of `x.len()`, `l`, `reach` (`nc` cells per side), cell c holding
    /// `x[starts[c]..starts[c + 1]]`. Each cell's particles are then its chain of `build` in
    /// order, so the pairs are `build`'s, in its order; the cells are cut into `parts`
    /// ranges of about equal numbers of particles, whose pairs are found on the current
    /// rayon pool or team and joined in cell order (the same list for any `parts`).
    pub fn build_by_cell(
        &mut self,
        x: &[[f64; D]],
        l: f64,
        reach: f64,
        nc: usize,
        starts: &[u32],
        parts: usize,
    ) {
        let ncells = nc.pow(D as u32);
        debug_assert_eq!(starts.len(), ncells + 1);
        debug_assert_eq!(starts[ncells] as usize, x.len());
        let n = x.len();
        let parts = parts.clamp(1, ncells);
        // Cell c0 of each part: the first cell whose start reaches k n / parts.
        let mut bounds = vec![0usize; parts + 1];
        bounds[parts] = ncells;
        for (k, b) in bounds.iter_mut().enumerate().take(parts).skip(1) {
            let want = (k * n / parts) as u32;
            *b = starts[..ncells].partition_point(|&s| s < want);
        }
        for k in 1..=parts {
            bounds[k] = bounds[k].max(bounds[k - 1]);
        }
        self.part_pairs.resize_with(parts, Vec::new);
        let r2 = reach * reach;
        let work = |k: usize, out: &mut Vec<Pair<D>>| {
            out.clear();
            for c in bounds[k]..bounds[k + 1] {
                cell_pairs(x, l, r2, nc, starts, c, out);
            }
        };
        let mut jobs: Vec<_> = self.part_pairs[..parts].iter_mut().enumerate().collect();
        super::team::run_parts(&mut jobs, parts, &|(k, out)| work(*k, out));
        self.pairs.clear();
        for p in &self.part_pairs[..parts] {
            self.pairs.extend_from_slice(p);
        }
    }
}

/// The pairs that [`NeighbourList::build`] finds from cell `c` (positions stored by cell,
/// `starts` as in [`NeighbourList::build_by_cell`]), in its order, appended to `out`.
fn cell_pairs<const D: usize>(
    x: &[[f64; D]],
    l: f64,
    r2: f64,
    nc: usize,
    starts: &[u32],
    c: usize,
    out: &mut Vec<Pair<D>>,
) {
    let (s0, e0) = (starts[c] as usize, starts[c + 1] as usize);
    if s0 == e0 {
        return;
    }
    half_stencil::<D>(c, nc, |c2| {
        let e2 = starts[c2 + 1] as usize;
        for i in s0..e0 {
            // The cell itself: each pair once (j after i).
            let s2 = if c2 == c { i + 1 } else { starts[c2] as usize };
            for j in s2..e2 {
                out.extend(near_pair(x, l, r2, i, j));
            }
        }
    });
}

/// The pair (i, j), ordered by index, with its image shift, if closer than sqrt(`r2`) under
/// the minimum image.
#[inline(always)]
fn near_pair<const D: usize>(
    x: &[[f64; D]],
    l: f64,
    r2: f64,
    i: usize,
    j: usize,
) -> Option<Pair<D>> {
    let (i, j) = if i < j { (i, j) } else { (j, i) };
    let mut d2 = 0.0;
    let mut shift = [0.0; D];
    for k in 0..D {
        let dx = x[i][k] - x[j][k];
        let m = min_image(dx, l);
        shift[k] = m - dx;
        d2 += m * m;
    }
    (d2 < r2).then_some(Pair {
        i: i as u32,
        j: j as u32,
        shift,
    })
}

/// The half stencil of cell `c` in a periodic grid of `nc >= 3` cells per side: `f` gets,
/// in the order of the offsets in {-1, 0, 1}^D (first component fastest), every neighbour
/// cell with an index above c, and c itself at the zero offset (the only offset that maps
/// a cell onto itself when nc >= 3).
#[inline(always)]
fn half_stencil<const D: usize>(c: usize, nc: usize, mut f: impl FnMut(usize)) {
    let n_off = 3usize.pow(D as u32);
    let mut cc = [0usize; D];
    let mut rem = c;
    for ck in cc.iter_mut() {
        *ck = rem % nc;
        rem /= nc;
    }
    for o in 0..n_off {
        let mut nb = [0usize; D];
        let mut r = o;
        for k in 0..D {
            // cc[k] + off wrapped into [0, nc) (off in {-1, 0, 1}, nc >= 3): no division.
            let off = r % 3;
            r /= 3;
            nb[k] = match off {
                0 if cc[k] == 0 => nc - 1,
                0 => cc[k] - 1,
                1 => cc[k],
                _ if cc[k] + 1 == nc => 0,
                _ => cc[k] + 1,
            };
        }
        let c2 = nb.iter().rev().fold(0, |acc, &ck| acc * nc + ck);
        if c2 > c || (c2 == c && o == (n_off - 1) / 2) {
            f(c2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::RunRng;

    /// `round_near` and `floor_near` are `round` and `floor` bit for bit (signs of zero
    /// and NaN included): at the branch edges (+-0.5, +-1.5, 0, 1 and their neighbouring
    /// doubles), at special values, and at 10^6 draws spread over (-3, 3) and over the
    /// differences of wrapped positions. A wrong edge (e.g. `q > 0.5`) or a lost zero sign
    /// fails here.
    #[test]
    fn fast_rounding() {
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let up = |x: f64| {
            f64::from_bits(if x >= 0.0 {
                x.to_bits() + 1
            } else {
                x.to_bits() - 1
            })
        };
        let down = |x: f64| {
            if x == 0.0 {
                -f64::from_bits(1)
            } else {
                f64::from_bits(if x > 0.0 {
                    x.to_bits() - 1
                } else {
                    x.to_bits() + 1
                })
            }
        };
        let mut qs = vec![
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::from_bits(1),
            -f64::from_bits(1),
            1e300,
            -1e300,
        ];
        for e in [0.5, 1.5, 1.0, 2.5, -0.5, -1.5, -1.0, -2.5] {
            qs.extend([e, up(e), down(e), up(up(e)), down(down(e))]);
        }
        let mut rng = RunRng::new(11);
        for _ in 0..1_000_000 {
            qs.push(6.0 * rng.f64() - 3.0);
            let (a, b) = (rng.f64(), rng.f64());
            qs.push((a - b) / 1.0);
        }
        for &q in &qs {
            assert!(
                same(round_near(q), q.round()),
                "round {q:e}: {}",
                round_near(q)
            );
            assert!(
                same(floor_near(q), q.floor()),
                "floor {q:e}: {}",
                floor_near(q)
            );
        }
        // min_image and wrap as their formulas with the libm calls.
        for w in qs.chunks_exact(2) {
            let (dx, l) = (w[0], 3.7);
            assert!(
                same(min_image(dx, l), dx - l * (dx / l).round()),
                "min_image {dx:e}"
            );
            let y = w[1] - l * (w[1] / l).floor();
            let want = if y >= l { 0.0 } else { y };
            assert!(same(wrap(w[1], l), want), "wrap {:e}", w[1]);
        }
    }

    /// For points stored by cell (cell order, index order within a cell), the list built
    /// by cell ranges on 1, 2 and 3 parts is `build`'s list, pair for pair and bit for bit
    /// (shifts included), in its order; also with a grid of 3 cells per side (wrapping
    /// stencils) and points on cell boundaries.
    #[test]
    fn build_by_cell_is_build() {
        let mut rng = RunRng::new(8);
        for (n, l, reach) in [(3000usize, 1.0, 0.05), (400, 1.0, 0.3), (2000, 0.2, 0.011)] {
            let mut x: Vec<[f64; 2]> = (0..n)
                .map(|k| {
                    if k % 50 == 0 {
                        // On a cell boundary.
                        let (nc, side) = cell_grid::<2>(n, l, reach).unwrap();
                        [(k % nc) as f64 * side, rng.f64() * l]
                    } else {
                        [rng.f64() * l, rng.f64() * l]
                    }
                })
                .collect();
            let (nc, side) = cell_grid::<2>(n, l, reach).unwrap();
            let mut keyed: Vec<(usize, usize)> =
                (0..n).map(|i| (cell_index(&x[i], nc, side), i)).collect();
            keyed.sort();
            x = keyed.iter().map(|&(_, i)| x[i]).collect();
            let mut starts = vec![0u32; nc * nc + 1];
            for &(c, _) in &keyed {
                starts[c + 1] += 1;
            }
            for c in 0..nc * nc {
                starts[c + 1] += starts[c];
            }
            let mut want = NeighbourList::<2>::default();
            want.build(&x, l, reach);
            assert!(!want.pairs.is_empty());
            let bits = |p: &Pair<2>| (p.i, p.j, p.shift.map(f64::to_bits));
            for parts in [1, 2, 3] {
                let mut got = NeighbourList::<2>::default();
                got.build_by_cell(&x, l, reach, nc, &starts, parts);
                assert_eq!(got.pairs.len(), want.pairs.len(), "n {n} parts {parts}");
                assert!(
                    got.pairs.iter().map(bits).eq(want.pairs.iter().map(bits)),
                    "n {n} parts {parts}"
                );
            }
        }
    }

    /// The cell-built list equals the all-pairs list (as sets) for random points, in 2D with
    /// several grid sizes including the all-pairs fallback.
    #[test]
    fn cell_list_matches_all_pairs() {
        let mut rng = RunRng::new(3);
        for (n, l, reach) in [(500usize, 1.0, 0.07), (300, 1.0, 0.2), (50, 1.0, 0.4)] {
            let x: Vec<[f64; 2]> = (0..n).map(|_| [rng.f64() * l, rng.f64() * l]).collect();
            let mut nl = NeighbourList::<2>::default();
            nl.build(&x, l, reach);
            let mut got: Vec<(u32, u32)> = nl.pairs.iter().map(|p| (p.i, p.j)).collect();
            got.sort();
            let mut want = Vec::new();
            for i in 0..n {
                for j in i + 1..n {
                    let d2: f64 = (0..2)
                        .map(|k| min_image(x[i][k] - x[j][k], l).powi(2))
                        .sum();
                    if d2 < reach * reach {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(got, want);
            for p in &nl.pairs {
                for k in 0..2 {
                    let s = x[p.i as usize][k] - x[p.j as usize][k] + p.shift[k];
                    assert!(s.abs() <= reach);
                }
            }
        }
    }
}
