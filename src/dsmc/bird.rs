//! Bird's method (paper section III.B, spec section 3), the baseline.
//!
//! Ordered pairs of distinct particles are drawn uniformly from all N, e uniformly on the
//! sphere, and the trial is accepted with sigma_ab^2 |g.e| / C_max, where
//! C_max = 2 max_j ((sigma_j + sigma_M)/2)^2 |v_j| (48-49). Trials are a Poisson process of
//! rate N^2 C_max pi / V (50).

use super::collision::{collide, uniform_direction};
use super::{
    drift, prefetch, speed_bound, Candidate, DsmcSim, PhysicsError, PIPELINE_DEPTH, RAISE_SLACK,
};

/// How many trials ahead of use a candidate's velocity lines are prefetched.
const STAGE: usize = 8;

/// Bird's per-particle rejection bound: an f32 upper bound on ((sigma_j + sigma_M)/2)^2 |v_j|.
#[inline(always)]
pub fn bird_weight(v: &[f64; 3], sigma: f64, sigma_max: f64) -> f32 {
    let c = 0.25 * (sigma + sigma_max) * (sigma + sigma_max);
    let w = speed_bound(v) as f64 * c * (1.0 + 1e-7);
    let f = w as f32;
    if (f as f64) < w {
        f.next_up()
    } else {
        f
    }
}

impl DsmcSim {
    #[inline(always)]
    fn species_of(&self, p: usize) -> usize {
        self.off.partition_point(|&o| o <= p) - 1
    }

    pub(super) fn advance_bird(&mut self, max_trials: u64) -> Result<bool, PhysicsError> {
        let msd = self.sys.displacements();
        let n = self.sys.n_particles();
        let sig_max = self.sys.sigma_max();
        if self.rate <= 0.0 {
            return self.idle_to_end();
        }
        let mut trials = 0u64;
        let result = loop {
            if trials >= max_trials {
                break Ok(false);
            }
            trials += 1;
            self.gap_trial();
            if self.ring.len() <= PIPELINE_DEPTH / 2 {
                for _ in 0..PIPELINE_DEPTH / 2 {
                    let (a, b) = self.rng.below_pair(n, n);
                    let u = self.rng.f64();
                    prefetch(self.speed.as_ptr().wrapping_add(a));
                    prefetch(self.speed.as_ptr().wrapping_add(b));
                    self.ring.push(Candidate {
                        i: 0,
                        k: 0,
                        a: a as u32,
                        b: b as u32,
                        u,
                        gap: 0.0,
                    });
                }
            }
            {
                let c2 = *self.ring.peek(STAGE);
                let (a2, b2) = (c2.a as usize, c2.b as usize);
                if c2.u * 2.0 * self.st.bird_bound < (self.speed[a2] + self.speed[b2]) as f64 {
                    prefetch(self.st.vel.as_ptr().wrapping_add(a2));
                    prefetch(self.st.vel.as_ptr().wrapping_add(b2));
                }
            }
            let c = self.ring.pop();
            let (a, b) = (c.a as usize, c.b as usize);
            let u = c.u;
            // sigma_ab^2 |g.e| <= sigma_ab^2 (|v_a| + |v_b|) <= w_a + w_b with
            // w_j >= ((sigma_j + sigma_M)/2)^2 |v_j|: a certain rejection without the velocities.
            if a == b || u * 2.0 * self.st.bird_bound >= (self.speed[a] + self.speed[b]) as f64 {
                continue;
            }
            let e = uniform_direction(&mut self.rng);
            let va = self.st.vel[a];
            let vb = self.st.vel[b];
            let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
            let gne = g[0] * e[0] + g[1] * e[1] + g[2] * e[2];
            let (i, k) = (self.species_of(a), self.species_of(b));
            let (si, sk) = (self.sys.species[i].diameter, self.sys.species[k].diameter);
            let sig2 = 0.25 * (si + sk) * (si + sk);
            if u * 2.0 * self.st.bird_bound >= sig2 * gne.abs() {
                continue;
            }
            let t = self.gap_time();
            let hit = Hit {
                a,
                b,
                e,
                t,
                va,
                vb,
                gne,
                i,
                k,
            };
            if let Some(done) = self.bird_collide(hit, msd, sig_max)? {
                break Ok(done);
            }
        };
        self.st.trials += trials;
        result
    }

    /// An accepted collision `hit` at its time: the outputs before it first, then (41) and
    /// the bounds. Some(done) when the run ends here (its end reached: the collision is not
    /// applied, it is the run's stop; or every particle at rest).
    #[inline(always)]
    fn bird_collide(
        &mut self,
        hit: Hit,
        msd: bool,
        sig_max: f64,
    ) -> Result<Option<bool>, PhysicsError> {
        let Hit {
            a,
            b,
            e,
            t,
            va,
            vb,
            mut gne,
            i,
            k,
        } = hit;
        if self.next_event <= t && self.outputs_before(t)? {
            self.stop = Some(super::Stop::Bird {
                a: a as u32,
                b: b as u32,
                e,
                t,
            });
            return Ok(Some(true));
        }
        self.st.t = t;
        // (41) is invariant under e -> -e: use the orientation with g.e > 0.
        let e = if gne < 0.0 {
            gne = -gne;
            [-e[0], -e[1], -e[2]]
        } else {
            e
        };
        if msd {
            drift(&mut self.st.disp[a], va, t);
            drift(&mut self.st.disp[b], vb, t);
        }
        let (si, sk) = (self.sys.species[i].diameter, self.sys.species[k].diameter);
        let (ma, mb) = (self.sys.species[i].mass, self.sys.species[k].mass);
        let (mut na, mut nb) = (va, vb);
        let eps = self.eps.eps(i, k, gne);
        collide(&mut na, &mut nb, ma, mb, eps, e, gne);
        self.st.vel[a] = na;
        self.st.vel[b] = nb;
        self.speed[a] = bird_weight(&na, si, sig_max);
        self.speed[b] = bird_weight(&nb, sk, sig_max);
        self.st.collisions += 1;
        self.st.species_collisions[i] += 1;
        self.st.species_collisions[k] += 1;
        let mut raised = false;
        for (s, v) in [(si, na), (sk, nb)] {
            let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let c = 0.25 * (s + sig_max) * (s + sig_max) * speed;
            if c > self.st.bird_bound {
                self.st.bird_bound = c * RAISE_SLACK;
                raised = true;
            }
        }
        if raised {
            // Candidates do not depend on the bound: keep the pipeline.
            self.st.bound_raises += 1;
            self.rebuild_rates();
        }
        if self.refresh_due() {
            self.refresh_bounds();
        }
        if self.rate <= 0.0 {
            return self.idle_to_end().map(Some);
        }
        Ok(None)
    }

    /// Continue a run that stopped at the collision of a and b (impact direction e) at time
    /// t: apply it as the longer run does. True if the run is done again.
    pub(super) fn resume_bird(
        &mut self,
        a: usize,
        b: usize,
        e: [f64; 3],
        t: f64,
    ) -> Result<bool, PhysicsError> {
        let sig_max = self.sys.sigma_max();
        let (va, vb) = (self.st.vel[a], self.st.vel[b]);
        let g = [va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]];
        let hit = Hit {
            a,
            b,
            e,
            t,
            va,
            vb,
            gne: g[0] * e[0] + g[1] * e[1] + g[2] * e[2],
            i: self.species_of(a),
            k: self.species_of(b),
        };
        Ok(self
            .bird_collide(hit, self.sys.displacements(), sig_max)?
            .unwrap_or(false))
    }
}

/// An accepted Bird trial: particles a, b (species i, k) with their velocities, the impact
/// direction e drawn for them, g.e, and the time.
struct Hit {
    a: usize,
    b: usize,
    e: [f64; 3],
    t: f64,
    va: [f64; 3],
    vb: [f64; 3],
    gne: f64,
    i: usize,
    k: usize,
}
