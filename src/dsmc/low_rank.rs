//! The low-rank method (paper section III.A, spec section 4).
//!
//! The majorant of the ordered species-pair rate, A_ik N_i N_k = pi/(4V) vmax_i
//! (sigma_i^2 + 2 sigma_i sigma_k + sigma_k^2) N_i N_k (42-43), has rank 3:
//! sum_r u_i^(r) w_k^(r) with u = N_i vmax_i (sigma_i^2, 2 sigma_i, 1) and w = N_k (1, sigma_k,
//! sigma_k^2). The w tables never change (counts are fixed); the (r, i) table changes only when
//! a speed bound does. Both are alias tables, so a species pair costs two 64-bit words.
//!
//! A trial proposes an ordered particle pair and accepts it with |g| / (vmax_i + vmax_k): the
//! two orders of a pair together are proposed at pi sigma^2 (vmax_i + vmax_k) / V, so the
//! accepted rate is pi sigma^2 |g| / V, the exact collision rate (36) integrated over e.
//! The impact direction is then drawn with density ~ cos(theta) around g.

use super::alias::Alias;
use super::collision::{collide, impact_direction};
use super::{
    prefetch, speed_bound, Candidate, DsmcSim, DsmcSystem, PhysicsError, PIPELINE_DEPTH,
    RAISE_SLACK,
};

/// How many trials ahead of use a candidate's velocity lines are prefetched.
const STAGE: usize = 8;

/// The three static tables over k: weights N_k, N_k sigma_k, N_k sigma_k^2.
pub fn static_tables(sys: &DsmcSystem) -> [Alias; 3] {
    let w = |p: i32| -> Vec<f64> {
        sys.species
            .iter()
            .map(|s| s.count as f64 * s.diameter.powi(p))
            .collect()
    };
    [Alias::new(&w(0)), Alias::new(&w(1)), Alias::new(&w(2))]
}

/// Weights of the (r, i) table: W_r u_i^(r), laid out r-major.
pub fn dynamic_weights(sys: &DsmcSystem, vmax: &[f64], k_tables: &[Alias; 3]) -> Vec<f64> {
    let m = sys.species.len();
    let mut w = Vec::with_capacity(3 * m);
    let factors = [|s: f64| s * s, |s: f64| 2.0 * s, |_s: f64| 1.0];
    for (r, f) in factors.iter().enumerate() {
        let wr = k_tables[r].total();
        for (i, sp) in sys.species.iter().enumerate() {
            w.push(wr * sp.count as f64 * vmax[i] * f(sp.diameter));
        }
    }
    w
}

impl DsmcSim {
    #[inline(always)]
    fn draw_candidate(&mut self) -> Candidate {
        let ri = self.pair_i.sample(self.rng.u64());
        // SAFETY: the slot tables have one entry per (r, i) slot; r < 3.
        let (r, i) = unsafe {
            (
                *self.slot_term.get_unchecked(ri) as usize,
                *self.slot_species.get_unchecked(ri) as usize,
            )
        };
        let k = unsafe { self.pair_k.get_unchecked(r) }.sample(self.rng.u64());
        let (da, db) = self
            .rng
            .below_pair(self.off[i + 1] - self.off[i], self.off[k + 1] - self.off[k]);
        let (a, b) = (self.off[i] + da, self.off[k] + db);
        let u = self.rng.f64();
        prefetch(self.speed.as_ptr().wrapping_add(a));
        prefetch(self.speed.as_ptr().wrapping_add(b));
        Candidate {
            i: i as u32,
            k: k as u32,
            a: a as u32,
            b: b as u32,
            u,
        }
    }

    pub(super) fn advance_low_rank(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        if self.rate <= 0.0 {
            return self.idle_to_end();
        }
        let msd = self.sys.displacements();
        let mut trials = 0u64;
        let result = loop {
            if trials >= max_trials {
                break Ok(false);
            }
            trials += 1;
            // Keep the pipeline at least half full, refilling in batches.
            while self.ring.len() < PIPELINE_DEPTH {
                let c = self.draw_candidate();
                self.ring.push(c);
            }
            // Stage 2: the candidate STAGE places ahead gets its velocity lines prefetched if
            // its (possibly stale) speed bounds do not already reject it.
            {
                let c2 = *self.ring.peek(STAGE);
                let (a2, b2) = (c2.a as usize, c2.b as usize);
                let u2 = c2.u * (self.st.vmax[c2.i as usize] + self.st.vmax[c2.k as usize]);
                if u2 < (self.speed[a2] + self.speed[b2]) as f64 {
                    prefetch(self.st.vel.as_ptr().wrapping_add(a2));
                    prefetch(self.st.vel.as_ptr().wrapping_add(b2));
                }
            }
            let c = self.ring.pop();
            self.gap_trial();
            let (a, b) = (c.a as usize, c.b as usize);
            let (i, k) = (c.i as usize, c.k as usize);
            let u = c.u * (self.st.vmax[i] + self.st.vmax[k]);
            // |g| <= |v_a| + |v_b| <= s_a + s_b: a certain rejection, decided without the
            // velocities (the same decision the full test below would make).
            if u >= (self.speed[a] + self.speed[b]) as f64 {
                continue;
            }
            let va = self.st.vel[a];
            let vb = self.st.vel[b];
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
            if u * u >= g2 {
                continue;
            }
            // Accepted: the collision happens at t_c; outputs before it see the old state.
            let t = self.gap_time();
            if self.next_event <= t && self.outputs_before(t)? {
                break Ok(true);
            }
            self.st.t = t;
            let gn = g2.sqrt();
            let (e, gne) = impact_direction(g, gn, &mut self.rng);
            if msd {
                for (p, v) in [(a, va), (b, vb)] {
                    let d = &mut self.st.disp[p];
                    let dt = t - d[3];
                    d[0] += v[0] * dt;
                    d[1] += v[1] * dt;
                    d[2] += v[2] * dt;
                    d[3] = t;
                }
            }
            let (ma, mb) = (self.sys.species[i].mass, self.sys.species[k].mass);
            let (mut na, mut nb) = (va, vb);
            let eps = self.eps.eps(i, k, gne);
            collide(&mut na, &mut nb, ma, mb, eps, e, gne);
            self.st.vel[a] = na;
            self.st.vel[b] = nb;
            self.speed[a] = speed_bound(&na);
            self.speed[b] = speed_bound(&nb);
            self.st.collisions += 1;
            self.st.species_collisions[i] += 1;
            self.st.species_collisions[k] += 1;
            // Raise bounds that a new speed exceeds (then every candidate drawn with the old
            // tables is void).
            let mut raised = false;
            for (s, v) in [(i, na), (k, nb)] {
                let s2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                if s2 > self.st.vmax[s] * self.st.vmax[s] {
                    self.st.vmax[s] = s2.sqrt() * RAISE_SLACK;
                    raised = true;
                }
            }
            if raised {
                self.st.bound_raises += 1;
                self.rebuild_rates();
                self.ring.clear();
            }
            if self.refresh_due() {
                self.refresh_bounds();
            }
            if self.rate <= 0.0 {
                break self.idle_to_end();
            }
        };
        self.st.trials += trials;
        result
    }
}
