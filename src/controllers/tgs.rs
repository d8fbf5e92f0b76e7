//! A replica of PhysX 5.3.1's TGS step for a gripper pinching an object (opt-in:
//! `SimConfig::pinch_solver`, docs/physics.md, "The pinch in PhysX's step").
//!
//! ManiSkill steps PhysX's temporal Gauss–Seidel solver; MuJoCo's step solves the same grasp
//! as one convex problem. Where a light arm squeezes a light object the two part: PhysX's
//! arm stalls short of its targets, and the velocity PhysX reports for a still arm is not
//! zero (docs/outcome-physics.md, "The stall" and "PhysX's reported velocity from the state
//! alone"). This module takes a physics step of the robot and the pinched object as PhysX
//! does, in joint space, following `DyTGSDynamics.cpp` (`iterativeSolveIsland`),
//! `DyTGSContactPrep.cpp` (`setupExtSolverContactStep`, `solveExtContactStep`),
//! `DyFrictionCorrelation.cpp` (`growPatches`) and the articulation drives
//! (`DyCpuGpuArticulation.h`):
//!
//! 1. The unconstrained velocity: `v += dt·M⁻¹(passive − bias + w)`, once for the whole
//!    step, `w` the object's weight (the env's wrench; the robot's links feel no gravity, as
//!    in ManiSkill). `M` is PhysX's inertia, MuJoCo's without the armature.
//! 2. [`SUB_STEPS`] sub-steps of `h = dt/15`, each: every contact patch (the jaws' convex
//!    parts against the object's box or sphere, [`super::convex::box_manifold`] and
//!    [`super::convex::sphere_manifold`], the first jaw's parts first;
//!    then the object's contacts with the scene, from MuJoCo), its normal rows then its
//!    friction anchors; then every joint drive in joint order; then the positions advance by
//!    `h·v`.
//!    * A normal row pushes the separation `s = s₀ + J·Δq` (Δq the motion since the step
//!      began) out at `min(0.8, 2/√15)·(−s)/h`, or lets a separated contact approach at
//!      `s/h`; its impulse accumulates over the step and never falls below zero.
//!    * Up to two friction anchors per patch (the two contact points farthest apart), each
//!      with two tangent rows solved as a pair, pull their drift since the step began back
//!      at `0.8/h`, weighted by `min(0.8, 2/√15)`, within the friction cone of the patch's
//!      accumulated normal impulse (PhysX's improved patch friction halves the cone with two
//!      anchors; a pad's patch with one anchor adds torsional friction). The rows of a
//!      robot link are softened by its CFM ([`CFM_SCALE`]).
//!    * A drive is PhysX's implicit spring `kp (q* − q − h v') + kd (v* − v')`, its impulse
//!      accumulated over the step and clamped to the force limit times `dt`.
//! 3. One velocity iteration: the contacts again with penetration counted as zero (no push
//!    out), the drives frozen. Positions do not move; the velocities it leaves are the ones
//!    PhysX reports and steps on with.
//!
//! The replica steps the robot and the object alone, so it takes a step only while the object
//! touches no other free body ([`PinchReplica::pinches`]); MuJoCo's step takes the others.
//!
//! PhysX's contact cache is kept as PhysX keeps it (`getFrictionPatches`): a jaw part's
//! friction anchors carry over to the next step unless its friction broke (was clamped in the
//! velocity iteration), the bodies turned its normal by more than about 2.5°, an anchor pair
//! came [`CORRELATION_DISTANCE`] apart along it, or the anchors no longer span a quarter of
//! the new contacts' extent. A kept anchor pulls the two bodies back to where they touched
//! when it was made. The cache is part of the env's saved state; a reset forgets it. The
//! jaws' grasp forces (`is_grasped`) are the step's contact impulses
//! ([`PinchReplica::contact_force`]). Nothing here allocates after [`PinchReplica::new`].
use nalgebra::{DMatrix, Matrix3, Vector3};

use super::convex::{
    box_manifold, sphere_manifold, BoxShape, ContactPoint, ConvexPart, ManifoldScratch,
    SPECULATIVE_DISTANCE,
};
use crate::mujoco::{Data, Model};

mod cache;
pub use cache::{
    CachedPatch, CACHED_PATCH_LEN, CORRELATION_DISTANCE, FRICTION_OFFSET_THRESHOLD, SAME_NORMAL,
};

/// The object geoms the replica has manifolds for (MuJoCo geom types): a box or a sphere.
pub const OBJECT_GEOM_TYPES: [std::ffi::c_int; 2] =
    [crate::mujoco::GEOM_BOX, crate::mujoco::GEOM_SPHERE];
/// PhysX TGS position iterations per step (ManiSkill's `solver_position_iterations`).
pub const SUB_STEPS: usize = 15;
/// PhysX's push-out and friction weight: `min(0.8, 2/√SUB_STEPS)`.
pub fn bias_coefficient() -> f64 {
    (2.0 / (SUB_STEPS as f64).sqrt()).min(0.8)
}
/// PhysX's friction anchor bias: the drift is pulled back at this fraction per sub-step.
pub const FRICTION_BIAS: f64 = 0.8;
/// PhysX's `cfmScale` of an articulation link: its contacts are softened by this fraction of
/// the link's largest linear self-response.
pub const CFM_SCALE: f64 = 0.025;
/// ManiSkill's gripper pads' friction (static = dynamic) and the default material's; PhysX
/// averages the two materials of a pair.
pub const GRIPPER_FRICTION: f64 = 2.0;
/// The default material's friction (every other shape).
pub const DEFAULT_FRICTION: f64 = 0.3;
/// ManiSkill's `patch_radius` and `min_patch_radius` of the gripper pads (m): the lever of
/// PhysX's torsional friction on a patch with one anchor.
pub const PATCH_RADIUS: f64 = 0.1;
/// ManiSkill's `contact_offset` (m): PhysX makes a shape's contacts from this far apart and
/// solves the separated ones as speculative contacts. A sphere object's scene contacts come
/// from this far (the env gives its geoms this MuJoCo margin).
pub const CONTACT_OFFSET: f64 = 0.02;
/// Most contact points the replica solves in one step (the jaws' parts make at most four
/// each; the object's scene contacts fill the rest).
pub const MAX_POINTS: usize = 48;
/// Most contact patches.
pub const MAX_PATCHES: usize = 16;

/// A jaw's convex part: its body, its jaw (0 or 1) and the part.
pub type JawPart = (usize, usize, ConvexPart);

/// One drive as the replica needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplicaDrive {
    /// Index into the replica's dofs.
    pub local: usize,
    /// Stiffness, damping, force limit.
    pub kp: f64,
    /// Damping.
    pub kd: f64,
    /// Force limit.
    pub force_limit: f64,
}

/// A contact patch: points `start..end` of the point list, sharing one normal, one pair of
/// bodies and one friction coefficient.
#[derive(Debug, Clone, Copy, Default)]
struct Patch {
    start: usize,
    end: usize,
    friction: f64,
    /// The jaw part whose contacts these are (its slot in the friction cache), or
    /// `usize::MAX` for the object's scene contacts (never cached).
    slot: usize,
    /// The friction anchors (count 0..=2): on body 0 in its frame, on body 1 in its frame
    /// (world coordinates for the world).
    anchor_count: usize,
    anchor0: [Vector3<f64>; 2],
    anchor1: [Vector3<f64>; 2],
    /// The prep's floor of the accumulated normal impulse.
    min_normal: f64,
    /// The softening of its rows (the articulation link's CFM).
    cfm: f64,
    /// The torsional friction's lever (m; 0: none).
    torsion: f64,
    /// Whether the last pass clamped the patch's friction (PhysX then drops its anchors).
    broken: bool,
}

/// One contact point's row data.
#[derive(Debug, Clone, Copy, Default)]
struct PointRow {
    separation: f64,
    /// `−0.516/h` for a penetrating contact, `−1/h` for a separated one.
    bias_coef: f64,
    /// `1 / (J M⁻¹ Jᵀ + cfm)`.
    recip: f64,
    applied: f64,
}

/// One friction row (a tangent direction at an anchor).
#[derive(Debug, Clone, Copy, Default)]
struct FrictionRow {
    /// The row's direction (world).
    dir: Vector3<f64>,
    vel_mult: f64,
    applied: f64,
    /// The anchors' drift along the row at the start of the step.
    error: f64,
}

/// The replica's state and scratch buffers.
#[derive(Debug, Clone)]
pub struct PinchReplica {
    /// The jaws' convex parts: (body, side 0 or 1, part).
    parts: Vec<JawPart>,
    /// The object: body, box geom, its free joint's dof and qpos addresses.
    object_body: usize,
    object_geom: usize,
    /// The robot's bodies (to tell the object's scene contacts from its robot contacts).
    robot_body: Vec<bool>,
    /// Global dof of each local dof: the robot's, then the object's six.
    dofs: Vec<usize>,
    /// qpos address ranges (start, len) of the joints of the local dofs, for writing back.
    qpos_ranges: Vec<(usize, usize)>,
    drives: Vec<ReplicaDrive>,
    // Scratch.
    full_m: Vec<f64>,
    minv: DMatrix<f64>,
    m_local: DMatrix<f64>,
    jacp0: Vec<f64>,
    jacr0: Vec<f64>,
    jacp1: Vec<f64>,
    jacr1: Vec<f64>,
    force: Vec<f64>,
    a0: Vec<f64>,
    v: Vec<f64>,
    dq: Vec<f64>,
    q: Vec<f64>,
    qvel_global: Vec<f64>,
    qpos_new: Vec<f64>,
    points: Vec<ContactPoint>,
    /// Per point: body 0 (moves along the normal) and body 1; usize::MAX for the world.
    point_bodies: Vec<(usize, usize)>,
    rows: Vec<PointRow>,
    patches: Vec<Patch>,
    /// Per point: the normal row's J (n) and M⁻¹Jᵀ (n).
    j_n: Vec<f64>,
    w_n: Vec<f64>,
    /// Per anchor (2 per patch): two tangent rows' J and M⁻¹Jᵀ.
    j_t: Vec<f64>,
    w_t: Vec<f64>,
    frows: Vec<FrictionRow>,
    drive_sum: Vec<f64>,
    /// One row's J and M⁻¹Jᵀ while it is built.
    jbuf: Vec<f64>,
    wbuf: Vec<f64>,
    manifold: ManifoldScratch,
    /// PhysX's contact cache: per jaw part, the friction patch of the last step.
    cache: Vec<CachedPatch>,
    /// Whether the last step was taken by the replica.
    active: bool,
}

impl PinchReplica {
    /// A replica for the robot whose bodies are flagged in `robot_body`, with `robot_dofs`
    /// (the dofs of its kinematic tree), its `drives` (local indices into `robot_dofs`), the
    /// jaws' convex parts (`(body, side, part)`; side 0 and 1 are the two jaws) and the object
    /// held: `object_body` with its box or sphere geom `object_geom`, on a free joint. Errors name what
    /// does not fit.
    pub fn new(
        model: &Model,
        robot_body: Vec<bool>,
        robot_dofs: &[usize],
        drives: Vec<ReplicaDrive>,
        parts: Vec<JawPart>,
        object_body: usize,
        object_geom: usize,
    ) -> Result<PinchReplica, String> {
        let jnt = model.body_jntadr()[object_body];
        if jnt < 0 || model.joint_type(jnt as usize) != crate::mujoco::JointType::Free {
            return Err(format!(
                "the pinched object (body {object_body}) is not a free body"
            ));
        }
        if !OBJECT_GEOM_TYPES.contains(&model.geom_type()[object_geom]) {
            return Err(format!(
                "the pinched object's geom {object_geom} is neither a box nor a sphere; the \
                 replica's manifolds are a box or a sphere against convex parts"
            ));
        }
        let jnt = jnt as usize;
        let obj_dof = model.jnt_dofadr()[jnt] as usize;
        let mut dofs: Vec<usize> = robot_dofs.to_vec();
        dofs.extend(obj_dof..obj_dof + 6);
        let mut qpos_ranges = Vec::new();
        for &d in robot_dofs {
            let j = model.dof_jntid()[d] as usize;
            qpos_ranges.push((model.jnt_qposadr()[j] as usize, 1));
        }
        qpos_ranges.push((model.jnt_qposadr()[jnt] as usize, 7));
        let n = dofs.len();
        let nv = model.nv();
        let max_vertices = parts.iter().map(|p| p.2.vertices.len()).max().unwrap_or(8);
        let n_parts = parts.len();
        Ok(PinchReplica {
            parts,
            object_body,
            object_geom,
            robot_body,
            qpos_ranges,
            drives,
            full_m: vec![0.0; nv * nv],
            minv: DMatrix::zeros(n, n),
            m_local: DMatrix::zeros(n, n),
            jacp0: vec![0.0; 3 * nv],
            jacr0: vec![0.0; 3 * nv],
            jacp1: vec![0.0; 3 * nv],
            jacr1: vec![0.0; 3 * nv],
            force: vec![0.0; n],
            a0: vec![0.0; n],
            v: vec![0.0; n],
            dq: vec![0.0; n],
            q: vec![0.0; n],
            qvel_global: vec![0.0; nv],
            qpos_new: vec![0.0; model.nq()],
            points: Vec::with_capacity(MAX_POINTS),
            point_bodies: Vec::with_capacity(MAX_POINTS),
            rows: Vec::with_capacity(MAX_POINTS),
            patches: Vec::with_capacity(MAX_PATCHES),
            j_n: vec![0.0; MAX_POINTS * n],
            w_n: vec![0.0; MAX_POINTS * n],
            j_t: vec![0.0; MAX_PATCHES * 4 * n],
            w_t: vec![0.0; MAX_PATCHES * 4 * n],
            frows: vec![FrictionRow::default(); MAX_PATCHES * 4],
            drive_sum: vec![0.0; n],
            jbuf: vec![0.0; n],
            wbuf: vec![0.0; n],
            manifold: ManifoldScratch::new(max_vertices),
            cache: vec![CachedPatch::default(); n_parts],
            active: false,
            dofs,
        })
    }

    /// Whether the last physics step was the replica's.
    pub fn active(&self) -> bool {
        self.active
    }

    /// Builds this step's contacts at the state of `data` (kinematics of [`Data::step1`])
    /// and returns whether both jaws touch the object (a pinch) while the object touches no
    /// other free body, so that the replica should take the step.
    pub fn pinches(&mut self, data: &Data) -> bool {
        self.points.clear();
        self.point_bodies.clear();
        self.patches.clear();
        let g = self.object_geom;
        let m = data.model();
        let gx = data.geom_xpos();
        let gm = data.geom_xmat();
        let size = m.geom_size();
        let bx = BoxShape {
            center: Vector3::new(gx[3 * g], gx[3 * g + 1], gx[3 * g + 2]),
            rot: mat3(&gm[9 * g..9 * g + 9]),
            half: Vector3::new(size[3 * g], size[3 * g + 1], size[3 * g + 2]),
        };
        // A sphere's radius (MuJoCo's first size); boxes use all three.
        let sphere = (m.geom_type()[g] == crate::mujoco::GEOM_SPHERE).then_some(size[3 * g]);
        let mut touching = [false; 2];
        let friction = 0.5 * (GRIPPER_FRICTION + DEFAULT_FRICTION);
        for (slot, (body, side, part)) in self.parts.iter().enumerate() {
            if self.patches.len() == MAX_PATCHES || self.points.len() + 4 > MAX_POINTS {
                break;
            }
            let b = *body;
            let (pos, rot) = body_pose(data, b);
            let start = self.points.len();
            let added = match sphere {
                Some(radius) => sphere_manifold(
                    part,
                    &pos,
                    &rot,
                    &bx.center,
                    radius,
                    SPECULATIVE_DISTANCE,
                    &mut self.points,
                ),
                None => box_manifold(
                    part,
                    &pos,
                    &rot,
                    &bx,
                    SPECULATIVE_DISTANCE,
                    &mut self.manifold,
                    &mut self.points,
                ),
            };
            if added == 0 {
                continue;
            }
            if self.points[start..].iter().any(|p| p.separation <= 0.0) {
                touching[*side] = true;
            }
            for _ in 0..added {
                // Body 0 is the jaw (the normal points from the box to the part).
                self.point_bodies.push((b, self.object_body));
            }
            self.patches.push(Patch {
                start,
                end: start + added,
                friction,
                slot,
                ..Patch::default()
            });
        }
        if !(touching[0] && touching[1]) {
            return false;
        }
        // The object's contacts with the scene (not the robot), from MuJoCo's collision: one
        // patch per geom pair.
        for i in 0..data.ncon() {
            let c = data.contact(i);
            let (b1, b2) = (
                m.geom_bodyid()[c.geom1] as usize,
                m.geom_bodyid()[c.geom2] as usize,
            );
            let other = if b1 == self.object_body {
                b2
            } else if b2 == self.object_body {
                b1
            } else {
                continue;
            };
            // A contact in a sphere's gap (its margin, `CONTACT_OFFSET`) is one of PhysX's
            // speculative contacts.
            let separated = c.in_gap;
            if self.robot_body[other] || (c.excluded && !separated) {
                continue;
            }
            if self.points.len() == MAX_POINTS {
                break;
            }
            // MuJoCo's normal points from geom1 to geom2; body 0 is the object.
            let mut n = Vector3::new(c.frame[0], c.frame[1], c.frame[2]);
            if b1 == self.object_body {
                n = -n;
            }
            if m.body_jntadr()[other] >= 0 && separated {
                // Not yet touching: the replica's step leaves that body where it is.
                continue;
            }
            if m.body_jntadr()[other] >= 0 {
                // The object touches another free body (PokeCube's peg the cube, StackCube's
                // cube the other): the replica steps only the robot and the object, so it
                // would meet that body as a wall. MuJoCo's step takes these steps.
                return false;
            }
            let pair_start = self.points.len();
            self.points.push(ContactPoint {
                pos: Vector3::from(c.pos),
                normal: n,
                separation: c.dist,
            });
            self.point_bodies.push((self.object_body, usize::MAX));
            let extends = self.patches.last().is_some_and(|p| {
                p.end == pair_start
                    && self.point_bodies[p.start] == self.point_bodies[pair_start]
                    && self.points[p.start].normal.dot(&n) > 0.999
            });
            if extends {
                if let Some(p) = self.patches.last_mut() {
                    p.end += 1;
                }
            } else if self.patches.len() < MAX_PATCHES {
                self.patches.push(Patch {
                    start: pair_start,
                    end: pair_start + 1,
                    friction: DEFAULT_FRICTION,
                    slot: usize::MAX,
                    ..Patch::default()
                });
            } else {
                self.points.pop();
                self.point_bodies.pop();
                break;
            }
        }
        for pi in 0..self.patches.len() {
            self.grow_anchors(data, pi);
        }
        true
    }

    /// Takes one PhysX step of length `dt` from the state of `data` (after
    /// [`Data::step1`] and a [`PinchReplica::pinches`] that returned true) with the drive
    /// targets `target_q`, `target_v` (per drive, in the order given to `new`), and keeps
    /// the resulting positions and velocities for [`PinchReplica::write`].
    pub fn step(&mut self, data: &Data, target_q: &[f64], target_v: &[f64]) {
        let n = self.dofs.len();
        let nv = data.model().nv();
        let dt = data.model().timestep();
        let h = dt / SUB_STEPS as f64;
        // PhysX's inertia: MuJoCo's without the armature.
        data.full_m(&mut self.full_m);
        let arm = data.model().dof_armature();
        for (a, &da) in self.dofs.iter().enumerate() {
            for (b, &db) in self.dofs.iter().enumerate() {
                self.m_local[(a, b)] =
                    self.full_m[da * nv + db] - if a == b { arm[da] } else { 0.0 };
            }
        }
        // M⁻¹ by Cholesky, in the buffers made by `new` (the factor takes `m_local`'s
        // storage and gives it back).
        let m = std::mem::replace(&mut self.m_local, DMatrix::zeros(0, 0));
        match nalgebra::Cholesky::new(m) {
            Some(chol) => {
                self.minv.fill_with_identity();
                chol.solve_mut(&mut self.minv);
                self.m_local = chol.unpack();
            }
            None => {
                // Not positive definite (a degenerate model): MuJoCo keeps the step.
                self.m_local = DMatrix::zeros(n, n);
                self.active = false;
                return;
            }
        }
        let (passive, bias, qvel, qpos) = (
            data.qfrc_passive(),
            data.qfrc_bias(),
            data.qvel(),
            data.qpos(),
        );
        for (a, &d) in self.dofs.iter().enumerate() {
            self.force[a] = passive[d] - bias[d];
            self.v[a] = qvel[d];
            self.dq[a] = 0.0;
        }
        // The object's weight: the env applies it as a wrench at its centre of mass (the
        // scene's gravity is off, as ManiSkill's robot links feel none).
        let b = self.object_body;
        let wrench: [f64; 6] = data.xfrc_applied()[6 * b..6 * b + 6]
            .try_into()
            .expect("six values");
        if wrench.iter().any(|&x| x != 0.0) {
            let xi = data.xipos();
            data.jac_point(
                b,
                [xi[3 * b], xi[3 * b + 1], xi[3 * b + 2]],
                &mut self.jacp0,
                &mut self.jacr0,
            );
            let nv = data.model().nv();
            for (a, &d) in self.dofs.iter().enumerate() {
                for r in 0..3 {
                    self.force[a] +=
                        self.jacp0[r * nv + d] * wrench[r] + self.jacr0[r * nv + d] * wrench[3 + r];
                }
            }
        }
        for a in 0..n {
            self.a0[a] = (0..n).map(|b| self.minv[(a, b)] * self.force[b]).sum();
        }
        for a in 0..n {
            self.v[a] += dt * self.a0[a];
        }
        for (k, d) in self.drives.iter().enumerate() {
            self.q[k] = qpos[self.qpos_ranges[d.local].0];
        }
        self.prepare_rows(data, h, dt);
        self.drive_sum.fill(0.0);
        for _ in 0..SUB_STEPS {
            self.solve_contacts(false, h);
            // The drives, in joint order.
            for (k, d) in self.drives.iter().enumerate() {
                let i = d.local;
                let g = h * d.kp + d.kd;
                let c = d.kp * (target_q[k] - self.q[k]) + d.kd * target_v[k];
                let w_ii = self.minv[(i, i)];
                let cap = d.force_limit * SUB_STEPS as f64;
                let f = ((c - g * self.v[i]) / (1.0 + h * g * w_ii))
                    .clamp(-cap - self.drive_sum[k], cap - self.drive_sum[k]);
                self.drive_sum[k] += f;
                for a in 0..n {
                    self.v[a] += h * self.minv[(a, i)] * f;
                }
            }
            for a in 0..n {
                self.dq[a] += h * self.v[a];
            }
            for (k, d) in self.drives.iter().enumerate() {
                self.q[k] += h * self.v[d.local];
            }
        }
        // The velocity iteration.
        self.solve_contacts(true, h);
        self.store_cache(data);
        // The new positions.
        self.qpos_new[..qpos.len()].copy_from_slice(qpos);
        self.qvel_global.fill(0.0);
        for (a, &d) in self.dofs.iter().enumerate() {
            self.qvel_global[d] = self.dq[a];
        }
        data.integrate_pos(&mut self.qpos_new, &self.qvel_global, 1.0);
        self.active = true;
    }

    /// Writes the step's positions and velocities of the robot and the object into `data`
    /// (after MuJoCo's own step, which keeps everything else).
    pub fn write(&self, data: &mut Data) {
        if !self.active {
            return;
        }
        {
            let qpos = data.qpos_mut();
            for &(start, len) in &self.qpos_ranges {
                qpos[start..start + len].copy_from_slice(&self.qpos_new[start..start + len]);
            }
        }
        let qvel = data.qvel_mut();
        for (a, &d) in self.dofs.iter().enumerate() {
            qvel[d] = self.v[a];
        }
    }

    /// The net contact force (world frame, N) the object exerted on `body` over the last
    /// step, if the replica took it: the accumulated normal and friction impulses of the
    /// body's jaw patches over the step's length, as PhysX reports contact forces.
    pub fn contact_force(&self, body: usize, dt: f64) -> Option<[f64; 3]> {
        if !self.active {
            return None;
        }
        let mut f = Vector3::zeros();
        for (pi, p) in self.patches.iter().enumerate() {
            if self.point_bodies[p.start] != (body, self.object_body) {
                continue;
            }
            for i in p.start..p.end {
                f += self.points[i].normal * self.rows[i].applied;
            }
            for k in 0..2 * p.anchor_count {
                let r = &self.frows[pi * 4 + k];
                f += r.dir * r.applied;
            }
        }
        f /= dt;
        Some([f.x, f.y, f.z])
    }

    /// Marks the replica idle for a step MuJoCo takes alone.
    pub fn idle(&mut self) {
        self.active = false;
        self.forget_contacts();
    }

    /// The Jacobian row `dir · (J₀(p) − J₁(p))` over the local dofs into `out`.
    fn row(
        &mut self,
        data: &Data,
        p: &Vector3<f64>,
        bodies: (usize, usize),
        dir: &Vector3<f64>,
        out: &mut [f64],
    ) {
        self.row2(data, p, p, bodies, dir, out);
    }

    /// The Jacobian row `dir · (J₀(p₀) − J₁(p₁))` over the local dofs into `out`: body 0's
    /// point `p0` against body 1's `p1`.
    fn row2(
        &mut self,
        data: &Data,
        p0: &Vector3<f64>,
        p1: &Vector3<f64>,
        bodies: (usize, usize),
        dir: &Vector3<f64>,
        out: &mut [f64],
    ) {
        let nv = data.model().nv();
        data.jac_point(
            bodies.0,
            [p0.x, p0.y, p0.z],
            &mut self.jacp0,
            &mut self.jacr0,
        );
        if bodies.1 != usize::MAX {
            data.jac_point(
                bodies.1,
                [p1.x, p1.y, p1.z],
                &mut self.jacp1,
                &mut self.jacr1,
            );
        } else {
            self.jacp1.fill(0.0);
        }
        for (a, &d) in self.dofs.iter().enumerate() {
            out[a] = (0..3)
                .map(|r| dir[r] * (self.jacp0[r * nv + d] - self.jacp1[r * nv + d]))
                .sum();
        }
    }

    /// The angular row `dir · (ω₀ − ω₁)` over the local dofs into `out`.
    fn angular_row(
        &mut self,
        data: &Data,
        bodies: (usize, usize),
        dir: &Vector3<f64>,
        out: &mut [f64],
    ) {
        let nv = data.model().nv();
        data.jac_point(bodies.0, [0.0; 3], &mut self.jacp0, &mut self.jacr0);
        if bodies.1 != usize::MAX {
            data.jac_point(bodies.1, [0.0; 3], &mut self.jacp1, &mut self.jacr1);
        } else {
            self.jacr1.fill(0.0);
        }
        for (a, &d) in self.dofs.iter().enumerate() {
            out[a] = (0..3)
                .map(|r| dir[r] * (self.jacr0[r * nv + d] - self.jacr1[r * nv + d]))
                .sum();
        }
    }

    /// The contact rows of this step: Jacobians, responses, biases, and the anchors.
    fn prepare_rows(&mut self, data: &Data, h: f64, dt: f64) {
        let n = self.dofs.len();
        let coef = bias_coefficient();
        self.rows.clear();
        // The articulation link's CFM: CFM_SCALE times its largest linear self-response.
        let cfm_of = |s: &mut Self, body: usize| -> f64 {
            if body == usize::MAX || !s.robot_body[body] {
                return 0.0;
            }
            let nv = data.model().nv();
            let xi = data.xipos();
            let c = [xi[3 * body], xi[3 * body + 1], xi[3 * body + 2]];
            data.jac_point(body, c, &mut s.jacp0, &mut s.jacr0);
            let mut best: f64 = 0.0;
            for r in 0..3 {
                let mut resp = 0.0;
                for (a, &da) in s.dofs.iter().enumerate() {
                    for (b, &db) in s.dofs.iter().enumerate() {
                        resp += s.jacp0[r * nv + da] * s.minv[(a, b)] * s.jacp0[r * nv + db];
                    }
                }
                best = best.max(resp);
            }
            CFM_SCALE * best
        };
        let mut j = std::mem::take(&mut self.jbuf);
        let mut w = std::mem::take(&mut self.wbuf);
        for pi in 0..self.patches.len() {
            let bodies = self.point_bodies[self.patches[pi].start];
            self.patches[pi].cfm = cfm_of(self, bodies.0).max(cfm_of(self, bodies.1));
        }
        for pi in 0..self.patches.len() {
            let (start, end, cfm) = (
                self.patches[pi].start,
                self.patches[pi].end,
                self.patches[pi].cfm,
            );
            for i in start..end {
                let p = self.points[i];
                let bodies = self.point_bodies[i];
                self.row(data, &p.pos, bodies, &p.normal, &mut j);
                let resp = self.response(&j, &mut w);
                self.j_n[i * n..(i + 1) * n].copy_from_slice(&j);
                self.w_n[i * n..(i + 1) * n].copy_from_slice(&w[..n]);
                let recip = if resp > 0.0 { 1.0 / (resp + cfm) } else { 0.0 };
                self.rows.push(PointRow {
                    separation: p.separation,
                    bias_coef: if p.separation > 0.0 {
                        -1.0 / h
                    } else {
                        -coef / h
                    },
                    recip,
                    applied: 0.0,
                });
            }
        }
        // Anchors and the prep's normal-impulse floor, per patch.
        for pi in 0..self.patches.len() {
            let patch = self.patches[pi];
            let mut floor = 0.0;
            for i in patch.start..patch.end {
                let vrel: f64 = (0..n).map(|a| self.j_n[i * n + a] * self.v[a]).sum();
                let pen_inv = self.rows[i].separation / (dt + h);
                floor += ((-pen_inv - vrel) * self.rows[i].recip).max(0.0);
            }
            let count = (patch.end - patch.start) as f64;
            let p = &mut self.patches[pi];
            p.min_normal = floor / count * 0.25;
            p.broken = false;
            let (anchor_count, anchor0, anchor1) = (p.anchor_count, p.anchor0, p.anchor1);
            // Two tangent directions per anchor, from the bodies' relative velocity.
            let i0 = patch.start;
            let normal = self.points[i0].normal;
            let bodies = self.point_bodies[i0];
            let (lin0, lin1) = (body_linear(data, bodies.0), body_linear(data, bodies.1));
            let vrel = lin0 - lin1;
            let mut t0 = vrel - normal * normal.dot(&vrel);
            if t0.norm_squared() <= 1e-4 {
                t0 = if normal.x.abs() < std::f64::consts::FRAC_1_SQRT_2 {
                    Vector3::new(0.0, -normal.z, normal.y)
                } else {
                    Vector3::new(-normal.y, normal.x, 0.0)
                };
            }
            let t0 = t0.normalize();
            let t1 = normal.cross(&t0);
            let (x0, r0) = body_pose(data, bodies.0);
            let (x1, r1) = body_pose(data, bodies.1);
            for a in 0..anchor_count {
                let (p0, p1) = (x0 + r0 * anchor0[a], x1 + r1 * anchor1[a]);
                for (k, t) in [t0, t1].iter().enumerate() {
                    let r = pi * 4 + a * 2 + k;
                    self.row2(data, &p0, &p1, bodies, t, &mut j);
                    let resp = self.response(&j, &mut w);
                    self.j_t[r * n..(r + 1) * n].copy_from_slice(&j);
                    self.w_t[r * n..(r + 1) * n].copy_from_slice(&w[..n]);
                    self.frows[r] = FrictionRow {
                        dir: *t,
                        vel_mult: if resp > f64::EPSILON {
                            coef / (resp + patch.cfm)
                        } else {
                            0.0
                        },
                        applied: 0.0,
                        error: (p0 - p1).dot(t),
                    };
                }
            }
            // PhysX's torsional friction on a one-anchor patch of a gripper pad (ManiSkill's
            // `patch_radius` and `min_patch_radius`): the bodies' relative turn about the
            // normal, within the cone times the patch radius.
            let torsion = if anchor_count == 1 && patch.slot != usize::MAX {
                let deepest = self.points[patch.start..patch.end]
                    .iter()
                    .map(|p| p.separation)
                    .fold(0.0, f64::min);
                PATCH_RADIUS.max((-deepest * PATCH_RADIUS).sqrt())
            } else {
                0.0
            };
            self.patches[pi].torsion = torsion;
            if torsion > 0.0 {
                let r = pi * 4 + 2;
                self.angular_row(data, bodies, &normal, &mut j);
                let resp = self.response(&j, &mut w);
                self.j_t[r * n..(r + 1) * n].copy_from_slice(&j);
                self.w_t[r * n..(r + 1) * n].copy_from_slice(&w[..n]);
                self.frows[r] = FrictionRow {
                    dir: Vector3::zeros(),
                    vel_mult: if resp > f64::EPSILON {
                        coef / (resp + patch.cfm)
                    } else {
                        0.0
                    },
                    applied: 0.0,
                    error: 0.0,
                };
            }
        }
        self.jbuf = j;
        self.wbuf = w;
    }

    /// `J M⁻¹ Jᵀ` of the row `j`, with `M⁻¹ Jᵀ` written into `w`.
    fn response(&self, j: &[f64], w: &mut [f64]) -> f64 {
        let n = self.dofs.len();
        for (a, wa) in w.iter_mut().enumerate().take(n) {
            *wa = (0..n).map(|b| self.minv[(a, b)] * j[b]).sum();
        }
        (0..n).map(|a| j[a] * w[a]).sum()
    }

    /// One pass over the contact patches: normal rows, then friction anchors.
    fn solve_contacts(&mut self, velocity_iteration: bool, h: f64) {
        let n = self.dofs.len();
        let min_pen = if velocity_iteration {
            0.0
        } else {
            f64::NEG_INFINITY
        };
        for pi in 0..self.patches.len() {
            let patch = self.patches[pi];
            let mut normal_sum = 0.0;
            for i in patch.start..patch.end {
                let jn = &self.j_n[i * n..(i + 1) * n];
                let row = &mut self.rows[i];
                let moved = dot(jn, &self.dq);
                let vel = dot(jn, &self.v);
                let sep = (row.separation + moved).max(min_pen);
                let bias = row.bias_coef * sep;
                let delta = (bias * row.recip - vel * row.recip).max(-row.applied);
                row.applied += delta;
                normal_sum += row.applied;
                axpy(&mut self.v, &self.w_n[i * n..(i + 1) * n], delta);
            }
            let normal = normal_sum.max(patch.min_normal);
            // PhysX's improved patch friction: two anchors share the patch's cone.
            let scale = if patch.anchor_count == 2 { 0.5 } else { 1.0 };
            let limit = patch.friction * normal * scale;
            for a in 0..patch.anchor_count {
                let r0 = pi * 4 + a * 2;
                let mut total = [0.0; 2];
                for (k, t) in total.iter_mut().enumerate() {
                    let r = r0 + k;
                    let jt = &self.j_t[r * n..(r + 1) * n];
                    let err = self.frows[r].error + dot(jt, &self.dq);
                    let vel = dot(jt, &self.v);
                    let bias = err * FRICTION_BIAS / h;
                    *t = self.frows[r].applied - self.frows[r].vel_mult * (vel + bias);
                }
                let mag = (total[0] * total[0] + total[1] * total[1]).sqrt();
                let clamped = mag > limit;
                let ratio = if clamped && mag > 0.0 {
                    limit / mag
                } else {
                    1.0
                };
                if velocity_iteration {
                    self.patches[pi].broken |= clamped;
                }
                for (k, t) in total.iter().enumerate() {
                    let r = r0 + k;
                    let new = t * ratio;
                    let delta = new - self.frows[r].applied;
                    self.frows[r].applied = new;
                    axpy(&mut self.v, &self.w_t[r * n..(r + 1) * n], delta);
                }
            }
            if patch.torsion > 0.0 {
                let r = pi * 4 + 2;
                let jt = &self.j_t[r * n..(r + 1) * n];
                let total = self.frows[r].applied - self.frows[r].vel_mult * dot(jt, &self.v);
                let limit = patch.friction * normal * patch.torsion;
                let clamped = total.abs() > limit;
                let new = if clamped {
                    total.clamp(-limit, limit)
                } else {
                    total
                };
                if velocity_iteration {
                    self.patches[pi].broken |= clamped;
                }
                let delta = new - self.frows[r].applied;
                self.frows[r].applied = new;
                axpy(&mut self.v, &self.w_t[r * n..(r + 1) * n], delta);
            }
        }
    }
}

/// `a · b` over the shorter length.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `v += s w`.
fn axpy(v: &mut [f64], w: &[f64], s: f64) {
    for (x, y) in v.iter_mut().zip(w) {
        *x += y * s;
    }
}

/// A body's frame in the world (the identity for the world, `usize::MAX`).
fn body_pose(data: &Data, body: usize) -> (Vector3<f64>, Matrix3<f64>) {
    if body == usize::MAX {
        return (Vector3::zeros(), Matrix3::identity());
    }
    let (x, m) = (data.xpos(), data.xmat());
    (
        Vector3::new(x[3 * body], x[3 * body + 1], x[3 * body + 2]),
        mat3(&m[9 * body..9 * body + 9]),
    )
}

/// A body's linear velocity at its centre of mass (zero for the world).
fn body_linear(data: &Data, body: usize) -> Vector3<f64> {
    if body == usize::MAX {
        return Vector3::zeros();
    }
    let v = data.body_velocity(body);
    Vector3::new(v[3], v[4], v[5])
}

/// A row-major 3×3 matrix.
fn mat3(m: &[f64]) -> Matrix3<f64> {
    Matrix3::new(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8])
}
