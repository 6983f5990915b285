//! Explicit central-difference time integration with lumped mass and mass-proportional damping,
//! prescribed displacements (with a smooth ramp), external loads, reactions and divergence checks.
//!
//! With `M ü + α M u̇ + f_int(u) = f_ext`, central differences give, per free component,
//! `u⁺ = [dt² (f_ext − f_int)/m + 2u − (1 − α dt/2) u⁻] / (1 + α dt/2)`.
//!
//! A per-node spring `−k u` (the hybrid model's interface pull) can be taken implicitly: the caller
//! puts its constant part in `f_ext` and `k` in [`Integrator::implicit_stiffness`], and the
//! denominator becomes `1 + α dt/2 + k dt²/m`, so a stiff pull on a light node cannot destabilize
//! the step.

use nalgebra::Vector3;
use rayon::prelude::*;

/// A prescribed displacement component.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prescribed {
    /// Node index.
    pub node: u32,
    /// Component (0 = x, 1 = y, 2 = z).
    pub axis: u8,
    /// Displacement reached at the end of the ramp, metres (0 for a fixed component).
    pub target: f32,
    /// Ramp duration, seconds (0: applied at once).
    pub ramp: f32,
    /// Reaction groups this component reports into, as a bit set (bit `g` for group `g`): a node
    /// on two reaction faces counts toward both.
    pub groups: u32,
}

/// The smooth ramp `s ↦ s³ (10 − 15 s + 6 s²)` (zero velocity and acceleration at both ends).
pub fn ramp(t: f32, duration: f32) -> f32 {
    if duration <= 0.0 {
        return 1.0;
    }
    let s = (t / duration).clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// Why a run stopped early.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Divergence {
    /// Step at which it was detected.
    pub step: u64,
    /// Simulated time then, seconds.
    pub time: f64,
    /// The node that diverged first (fastest, or non-finite).
    pub node: usize,
    /// What was seen.
    pub reason: String,
}

/// The state and scratch buffers of the integrator.
#[derive(Debug, Clone)]
pub struct Integrator {
    /// Displacement now, per node.
    pub u: Vec<Vector3<f32>>,
    /// Displacement one step ago.
    pub u_prev: Vec<Vector3<f32>>,
    /// Lumped mass per node, kg.
    pub mass: Vec<f32>,
    /// Whether each component is free.
    pub free: Vec<[bool; 3]>,
    /// Prescribed components.
    pub prescribed: Vec<Prescribed>,
    /// Mass-proportional damping α, 1/s.
    pub damping: f32,
    /// Time step, s.
    pub dt: f32,
    /// Steps taken.
    pub step: u64,
    /// Largest speed a node may reach before the run is declared divergent, m/s (a few times the
    /// dilatational wave speed: no stable run gets near it).
    pub speed_limit: f32,
    /// Reaction force per group after the last step, newtons.
    pub reactions: Vec<Vector3<f64>>,
    /// Per-node spring stiffness integrated implicitly (N/m); zero for most nodes.
    pub implicit_stiffness: Vec<f32>,
    /// Nodes that keep their displacement through a step (moved by another model, e.g. FLSM).
    pub frozen: Vec<bool>,
    next: Vec<Vector3<f32>>,
    /// When set ([`Integrator::set_active`]): the only nodes a step updates; every other node is
    /// held, with the same displacement in every buffer.
    active: Option<Vec<u32>>,
    /// The active nodes' new displacements, in the order of `active`.
    active_next: Vec<Vector3<f32>>,
}

impl Integrator {
    /// A body at rest.
    pub fn new(
        mass: Vec<f32>,
        prescribed: Vec<Prescribed>,
        groups: usize,
        damping: f32,
        dt: f32,
        speed_limit: f32,
    ) -> Self {
        let n = mass.len();
        let mut free = vec![[true; 3]; n];
        for p in &prescribed {
            free[p.node as usize][p.axis as usize] = false;
        }
        Self {
            u: vec![Vector3::zeros(); n],
            u_prev: vec![Vector3::zeros(); n],
            mass,
            free,
            prescribed,
            damping,
            dt,
            step: 0,
            speed_limit,
            reactions: vec![Vector3::zeros(); groups],
            implicit_stiffness: vec![0.0; n],
            frozen: vec![false; n],
            next: vec![Vector3::zeros(); n],
            active: None,
            active_next: Vec::new(),
        }
    }

    /// Steps only `active` nodes from now on (all nodes for `None`), in increasing order; every
    /// other node is held where it is (its velocity dropped now), and a step leaves its `u` and
    /// `u_prev` untouched. With few nodes active in a large body a step then costs what those
    /// nodes cost. The nodes left out must be frozen ([`Integrator::frozen`]) or massless, as a
    /// full step would leave them, and the prescribed nodes must be among the active ones.
    pub fn set_active(&mut self, active: Option<Vec<u32>>) {
        if let Some(nodes) = &active {
            let mut on = vec![false; self.u.len()];
            for &n in nodes {
                on[n as usize] = true;
            }
            for (n, _) in on.iter().enumerate().filter(|(_, on)| !**on) {
                self.u_prev[n] = self.u[n];
            }
        }
        self.active = active;
    }

    /// The nodes a step updates, when not all ([`Integrator::set_active`]).
    pub fn active(&self) -> Option<&[u32]> {
        self.active.as_deref()
    }

    /// Calls `f` with the active nodes (`None`: all) and the displacements now and a step ago,
    /// for a pass that moves nodes after a step (contacts).
    pub fn with_active<R>(
        &mut self,
        f: impl FnOnce(Option<&[u32]>, &mut [Vector3<f32>], &mut [Vector3<f32>]) -> R,
    ) -> R {
        f(self.active.as_deref(), &mut self.u, &mut self.u_prev)
    }

    /// Simulated time, seconds.
    pub fn time(&self) -> f64 {
        self.step as f64 * f64::from(self.dt)
    }

    /// Advances one step given internal and external forces at the current state.
    pub fn advance(&mut self, f_int: &[Vector3<f32>], f_ext: &[Vector3<f32>]) -> Result<(), Divergence> {
        self.advance_with(|i| f_int[i], f_ext)
    }

    /// Advances one step, asking `f_int` for each node's internal force as the update reaches it:
    /// with [`crate::Tled::node_force`] the force gather and the update are one pass over the nodes.
    pub fn advance_with<F>(&mut self, f_int: F, f_ext: &[Vector3<f32>]) -> Result<(), Divergence>
    where
        F: Fn(usize) -> Vector3<f32> + Sync,
    {
        let dt = self.dt;
        let a = 1.0 / (1.0 + 0.5 * self.damping * dt);
        let b = 1.0 - 0.5 * self.damping * dt;
        let dt2 = dt * dt;
        // Per node in parallel slabs; each slab reports its highest squared speed, and whether it
        // saw a non-finite one, without branches so the loop vectorizes. The fastest node is looked
        // up only when the step fails.
        let (max_speed2, finite) = if self.active.is_some() {
            self.update_active(&f_int, f_ext, [a, b, dt2])
        } else {
            let chunk = self.u.len().div_ceil(4 * rayon::current_num_threads().max(1)).max(1024);
            let arch = crate::model::simd_arch();
            // Take the output out so the runs can read `self` while writing it.
            let mut next = std::mem::take(&mut self.next);
            let this = &*self;
            let result = next
                .par_chunks_mut(chunk)
                .enumerate()
                .map(|(c, next)| {
                    arch.dispatch(UpdateRun {
                        it: this,
                        f_int: &f_int,
                        f_ext,
                        coeffs: [a, b, dt2],
                        first: c * chunk,
                        next,
                    })
                })
                .reduce(|| (0.0, true), |p, q| (p.0.max(q.0), p.1 && q.1));
            self.next = next;
            result
        };
        let max_speed2 = if finite { max_speed2 } else { f32::NAN };
        // Prescribed components, and the reactions they exert: r = m (ü + α u̇) + f_int − f_ext.
        let t_next = (self.step + 1) as f32 * dt;
        for p in &self.prescribed {
            self.next[p.node as usize][usize::from(p.axis)] = p.target * ramp(t_next, p.ramp);
        }
        let mut reactions = std::mem::take(&mut self.reactions);
        self.reactions_into(&f_int, f_ext, [&self.u_prev[..], &self.u[..], &self.next[..]], &mut reactions);
        self.reactions = reactions;
        if !max_speed2.is_finite() || max_speed2.sqrt() > self.speed_limit {
            let fastest = match &self.active {
                // Only the active nodes' `next` is this step's.
                Some(active) => fastest_node(&self.next, &self.u, dt, active.iter().map(|&i| i as usize)),
                None => fastest_node(&self.next, &self.u, dt, 0..self.u.len()),
            };
            return Err(Divergence {
                step: self.step + 1,
                time: f64::from(t_next),
                node: fastest,
                reason: if max_speed2.is_finite() {
                    format!(
                        "node {fastest} reached {:.3e} m/s, above the {:.3e} m/s limit",
                        max_speed2.sqrt(),
                        self.speed_limit
                    )
                } else {
                    format!("node {fastest} has a non-finite displacement")
                },
            });
        }
        match &self.active {
            // Only the active nodes move: the others keep `u` and `u_prev` as they are, whatever
            // another pass (a contact) wrote there.
            Some(active) => {
                for &i in active {
                    let i = i as usize;
                    self.u_prev[i] = self.u[i];
                    self.u[i] = self.next[i];
                }
            }
            None => {
                std::mem::swap(&mut self.u_prev, &mut self.u);
                std::mem::swap(&mut self.u, &mut self.next);
            }
        }
        self.step += 1;
        Ok(())
    }

    /// Node `i`'s displacement after the step: the damped central difference (with its implicit
    /// spring, if any), or where it is for a frozen or massless node. `[a, b, dt2]` are
    /// 1 / (1 + αdt/2), 1 − αdt/2 and dt².
    #[inline(always)]
    fn updated<F>(&self, i: usize, f_int: &F, f_ext: &[Vector3<f32>], [a, b, dt2]: [f32; 3]) -> Vector3<f32>
    where
        F: Fn(usize) -> Vector3<f32>,
    {
        let (m, u) = (self.mass[i], self.u[i]);
        if m > 0.0 && !self.frozen[i] {
            let k = self.implicit_stiffness[i];
            let denom = if k > 0.0 { 1.0 / (1.0 / a + k * dt2 / m) } else { a };
            ((f_ext[i] - f_int(i)) * (dt2 / m) + u * 2.0 - self.u_prev[i] * b) * denom
        } else {
            u
        }
    }

    /// The update of the active nodes alone ([`Integrator::set_active`]): their new displacements
    /// computed in parallel runs, then written into `next`; the highest squared speed and whether
    /// all were finite.
    fn update_active<F>(&mut self, f_int: &F, f_ext: &[Vector3<f32>], [a, b, dt2]: [f32; 3]) -> (f32, bool)
    where
        F: Fn(usize) -> Vector3<f32> + Sync,
    {
        let active = self.active.take().unwrap_or_default();
        let mut out = std::mem::take(&mut self.active_next);
        out.resize(active.len(), Vector3::zeros());
        let chunk = active.len().div_ceil(4 * rayon::current_num_threads().max(1)).max(256);
        let this = &*self;
        let inv_dt = 1.0 / this.dt;
        let result = active
            .par_chunks(chunk)
            .zip(out.par_chunks_mut(chunk))
            .map(|(nodes, out)| {
                let (mut worst, mut finite) = (0.0f32, true);
                for (&i, out) in nodes.iter().zip(out) {
                    let i = i as usize;
                    let (u, x) = (this.u[i], this.updated(i, f_int, f_ext, [a, b, dt2]));
                    *out = x;
                    let v2 = ((x - u) * inv_dt).norm_squared();
                    finite &= v2.is_finite();
                    worst = worst.max(v2);
                }
                (worst, finite)
            })
            .reduce(|| (0.0, true), |p, q| (p.0.max(q.0), p.1 && q.1));
        for (&i, x) in active.iter().zip(&out) {
            self.next[i as usize] = *x;
        }
        self.active_next = out;
        self.active = Some(active);
        result
    }

    /// The reactions of the prescribed components in the step from `u` to `next`
    /// (`[u_prev, u, next]`), with `f_int` the internal forces at `u`:
    /// `r = m (ü + α u̇) + f_int − f_ext + k u_next` per component, summed into each of its
    /// groups in `out`.
    pub fn reactions_into<F>(
        &self,
        f_int: F,
        f_ext: &[Vector3<f32>],
        [u_prev, u, next]: [&[Vector3<f32>]; 3],
        out: &mut [Vector3<f64>],
    ) where
        F: Fn(usize) -> Vector3<f32>,
    {
        let dt = self.dt;
        out.fill(Vector3::zeros());
        for p in self.prescribed.iter().filter(|p| p.groups != 0) {
            let (n, k) = (p.node as usize, usize::from(p.axis));
            let value = next[n][k];
            let acc = (value - 2.0 * u[n][k] + u_prev[n][k]) / (dt * dt);
            let vel = (value - u_prev[n][k]) / (2.0 * dt);
            let r = self.mass[n] * (acc + self.damping * vel) + f_int(n)[k] - f_ext[n][k]
                + self.implicit_stiffness[n] * value;
            for (g, reaction) in out.iter_mut().enumerate().take(32) {
                if p.groups & (1 << g) != 0 {
                    reaction[k] += f64::from(r);
                }
            }
        }
    }

    /// Kinetic energy from the last step's central velocity estimate, joules.
    pub fn kinetic_energy(&self) -> f64 {
        let dt = f64::from(self.dt);
        self.u
            .iter()
            .zip(&self.u_prev)
            .zip(&self.mass)
            .map(|((u, p), &m)| 0.5 * f64::from(m) * ((u - p).cast::<f64>() / dt).norm_squared())
            .sum()
    }
}

/// The central-difference update of one run of nodes, as a `pulp` operation (so it and the force
/// gather it calls run with the CPU's widest SIMD instructions). Returns the run's highest squared
/// speed and whether every speed was finite, computed without branches.
struct UpdateRun<'a, F> {
    it: &'a Integrator,
    f_int: &'a F,
    f_ext: &'a [Vector3<f32>],
    /// 1 / (1 + αdt/2), 1 − αdt/2 and dt².
    coeffs: [f32; 3],
    first: usize,
    next: &'a mut [Vector3<f32>],
}

impl<F: Fn(usize) -> Vector3<f32> + Sync> pulp::WithSimd for UpdateRun<'_, F> {
    type Output = (f32, bool);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> (f32, bool) {
        let UpdateRun { it, f_int, f_ext, coeffs: [a, b, dt2], first, next } = self;
        let inv_dt = 1.0 / it.dt;
        let (mut worst, mut finite) = (0.0f32, true);
        for (j, out) in next.iter_mut().enumerate() {
            let i = first + j;
            let (u, x) = (it.u[i], it.updated(i, f_int, f_ext, [a, b, dt2]));
            *out = x;
            let v2 = ((x - u) * inv_dt).norm_squared();
            finite &= v2.is_finite();
            worst = worst.max(v2);
        }
        (worst, finite)
    }
}

/// Of `nodes`, the one with a non-finite speed, or else the fastest one, between `u` and `next`.
fn fastest_node(
    next: &[Vector3<f32>],
    u: &[Vector3<f32>],
    dt: f32,
    nodes: impl Iterator<Item = usize> + Clone,
) -> usize {
    let speed2 = |i: usize| ((next[i] - u[i]) / dt).norm_squared();
    nodes
        .clone()
        .find(|&i| !speed2(i).is_finite())
        .unwrap_or_else(|| nodes.max_by(|&i, &j| speed2(i).total_cmp(&speed2(j))).unwrap_or(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_smooth_and_bounded() {
        assert_eq!(ramp(0.0, 1.0), 0.0);
        assert_eq!(ramp(2.0, 1.0), 1.0);
        assert!((ramp(0.5, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(ramp(0.3, 0.0), 1.0);
    }

    #[test]
    fn active_nodes_step_as_a_full_step_does_and_the_others_keep_what_was_written() {
        // Four nodes under gravity, node 1 frozen: stepping only nodes 0, 2 and 3 gives them the
        // full step's displacements; node 1, moved by another pass between steps, stays there.
        let gravity = [Vector3::new(0.0, 0.0, -9.81f32); 4];
        let mut full = Integrator::new(vec![1.0, 1.0, 2.0, 0.5], Vec::new(), 0, 3.0, 1e-3, 1e3);
        full.frozen[1] = true;
        let mut part = full.clone();
        part.set_active(Some(vec![0, 2, 3]));
        assert_eq!(part.active(), Some(&[0u32, 2, 3][..]));
        for step in 0..50 {
            full.advance(&[Vector3::zeros(); 4], &gravity).expect("stable");
            part.advance(&[Vector3::zeros(); 4], &gravity).expect("stable");
            if step == 20 {
                part.with_active(|_, u, u_prev| {
                    u[1].x = 0.25;
                    u_prev[1].x = 0.25;
                });
            }
        }
        for i in [0, 2, 3] {
            assert_eq!(part.u[i], full.u[i], "node {i}");
            assert_eq!(part.u_prev[i], full.u_prev[i], "node {i}");
        }
        assert_eq!(part.u[1], Vector3::new(0.25, 0.0, 0.0));
        assert_eq!(part.u_prev[1], part.u[1]);
        assert!(full.u[0].z < 0.0, "it fell");
    }

    #[test]
    fn harmonic_oscillator_matches_closed_form() {
        // One free dof, m = 1, k = 100: u(t) = cos(10 t) from u(0) = 1 at rest.
        let dt = 1e-3f32;
        let mut it = Integrator::new(vec![1.0], Vec::new(), 0, 0.0, dt, 1e3);
        it.u[0].x = 1.0;
        // Start at rest: u(−dt) = cos(10 dt).
        it.u_prev[0].x = (10.0 * dt).cos();
        for _ in 0..1000 {
            let f = [Vector3::new(100.0 * it.u[0].x, 0.0, 0.0)];
            it.advance(&f, &[Vector3::zeros()]).expect("stable");
        }
        let expected = (10.0f64 * 1.0).cos();
        assert!((f64::from(it.u[0].x) - expected).abs() < 1e-3, "{} vs {expected}", it.u[0].x);
    }
}
