//! Joint drives: PhysX's articulation drive law, applied at every physics substep.
//!
//! ManiSkill drives every controlled joint with a PhysX force drive: stiffness `kp`, damping
//! `kd`, force limit `F`, position target `q*` and velocity target `q̇*`. PhysX integrates
//! the drive *implicitly* — the force is computed against the joint velocity at the end of
//! the step — and clamps the whole force, damping included (`computeImplicitDriveParams
//! ForceDrive` / `computeDriveImpulse` in PhysX's `DyCpuGpuArticulation.h`):
//!
//! ```text
//! F = clamp( kp (q* − q − h q̇') + kd (q̇* − q̇'), −F_max, F_max ),   q̇' = q̇ + h W F
//! ```
//!
//! where `W` is the articulation's joint-space response (the drives' block of `M⁻¹`).
//!
//! [`Drives::apply`] computes the forces for one MuJoCo substep of length `h`:
//! * **Micro-steps.** PhysX's TGS solver integrates positions within its 10 ms step, in as
//!   many sub-steps as ManiSkill's `solver_position_iterations` (15); a single implicit step
//!   of 10 ms would lag the drive's slow mode. The drive dynamics `q̈ = a₀ + W F` (with the
//!   unconstrained acceleration `a₀` of the arm, frozen over the substep) are therefore
//!   integrated in [`MICRO_STEPS`] implicit micro-steps; the substep applies their mean
//!   force, so MuJoCo's explicit Euler step ends at the micro-integrated velocity.
//! * **Coupling.** Within a micro-step the drives of one articulation are solved as PhysX
//!   solves them: one pass in joint order, each drive's impulse computed with its own
//!   response `W_ii` from the velocity the drives before it left, then applied to every
//!   joint through `W` (sequential impulses). This is not the coupled implicit solution: with
//!   two nearly parallel joint axes (the Panda's joints 1 and 3 near a stretched elbow) the
//!   coupled solve moves joint 1 half as far again as PhysX in the first 50 ms
//!   (docs/physics.md, "Coupled drives"). The force limit bounds the impulse accumulated
//!   over the substep's micro-steps (`F h`), as PhysX clamps a drive's accumulated impulse:
//!   a saturated drive delivers its whole impulse early in the substep, and moves a few per
//!   cent further than under a force clamped at every instant.
//! * **Constraints.** Constraints that move an undriven joint (equalities on the WidowX AI's
//!   mimic carriage or the Robotiq linkage) or that a gripper pushes against (the contacts
//!   of a closing finger) are folded into `W` with MuJoCo's own compliance:
//!   `W − (J M⁻¹)ᵀ (J M⁻¹ Jᵀ + R)⁻¹ (J M⁻¹)`, so a drive sees the inertia it actually moves.
//!   PhysX solves contacts and drives in the same iterations; without the fold a finger
//!   reaching a free cube would only know its own inertia and fling the cube at the other
//!   finger, and a finger squeezing an object would get a fraction of its force.
//! * **Grippers.** With their contacts folded in, gripper joints use the same implicit law
//!   as the arm: a finger closing on a free cube pushes finger and cube together, one
//!   pressed between object and opposite finger (`W ≈ 0`) squeezes with the full spring
//!   force `clamp(kp (q* − q) + kd q̇*, ±F)`, as in PhysX.
//! * **The pinch's kick.** A gripper drive that moves an undriven follower through a
//!   constraint (the WidowX AI's mimic carriage, the Robotiq's linkage) and pinches an object
//!   squeezes with an impulse that, in PhysX, reaches the arm through the articulation
//!   (`W_arm,grip F`) and stays there: PhysX's held WidowX AI wrist drifts in proportion to the
//!   squeeze, about 10 mrad per 50 ms step at a 0.01 m carriage target, while MuJoCo, which
//!   solves contacts and forces together, cancels the kick. So such a drive's force stays out
//!   of the arm drives' micro-steps (they do not answer it), and the arm gets the kick as a
//!   generalised force `M a`, `a = W_arm,grip F`, which MuJoCo's contacts do not cancel.
//!   Grippers whose fingers are all driven (Panda, Fetch, SO100) get no kick: applied to
//!   them it parted the Panda's solver episodes from ManiSkill's (docs/physics.md, "The
//!   pinch's kick"). While the arm takes the kick, its joints report the velocity PhysX
//!   reports there ([`Drives::report_velocities`]), not their motion.
//! * **Position.** MuJoCo's semi-implicit Euler moves a joint by `h q̇'`; the micro-steps
//!   know the path within the substep. The difference `c` is applied as a generalised force
//!   `M c / h²` (so that what the arm holds moves with it through the contacts) and the
//!   extra velocity `c / h` is taken off after the step. Gripper joints, which end most
//!   substeps against an object, get neither the correction nor `a₀`.
//!
//! The forces are the controls of MuJoCo force actuators (gain 1, no bias, force range
//! ±F); contacts, joint limits and equalities stay implicit in MuJoCo's constraint solver.
use nalgebra::DMatrix;

use super::desc::Drive;
use super::tgs::{JawPart, PinchReplica, ReplicaDrive};

mod state;
use crate::mujoco::{Data, Model, ObjType};

/// Implicit micro-steps of the drive dynamics per physics substep: ManiSkill's
/// `solver_position_iterations` (15), PhysX TGS's sub-steps of its 10 ms step.
pub const MICRO_STEPS: usize = 15;
/// PhysX's default speed limit of an articulation joint (`PxArticulationJointReducedCoordinate::
/// setMaxJointVelocity`, 100 rad/s or m/s), which SAPIEN and ManiSkill keep: a driven joint's
/// velocity is clamped to it after every substep. Normal motion stays far below it (a free
/// Panda swing under saturated drives reaches a few rad/s); it bounds the runaway of an arm
/// that the IK has thrown onto another branch, which MuJoCo's explicit step would otherwise
/// let diverge.
pub const MAX_JOINT_VELOCITY: f64 = 100.0;
/// Substeps in a row a gripper must be sunk deeper than its release depth into an object before
/// it lets go (one control step at ManiSkill's 100 Hz physics and 20 Hz control).
pub const RELEASE_SUBSTEPS: u32 = 5;
/// Contact points of a face-on pinch: MuJoCo's box–box collider gives a face against a face
/// four (or more); its edge manifolds of three points overstate the depth (see
/// `Drives::release_deep_contacts`).
pub const FACE_CONTACTS: usize = 4;
/// Most gripper contacts folded into a substep's drive response (more are left to MuJoCo's
/// constraint solver alone; a two-finger grasp of a box makes at most 8).
pub const MAX_GRIPPER_CONTACTS: usize = 16;

/// One resolved drive.
#[derive(Debug, Clone, PartialEq)]
struct DriveDof {
    /// dof (qvel) address.
    dof: usize,
    /// qpos address.
    qpos: usize,
    /// Force actuator.
    actuator: usize,
    kp: f64,
    kd: f64,
    force_limit: f64,
    /// Arm joint (true) or gripper joint (false): see the module docs, "Position".
    arm: bool,
}

/// The drives of one robot: targets plus the force law. All buffers are allocated in
/// `Drives::new`; [`Drives::apply`] allocates nothing.
#[derive(Debug, Clone)]
pub struct Drives {
    dofs: Vec<DriveDof>,
    /// Drive index of every robot joint (ManiSkill order); None for undriven joints.
    by_joint: Vec<Option<usize>>,
    /// Position target per drive.
    target_q: Vec<f64>,
    /// Velocity target per drive.
    target_v: Vec<f64>,
    /// Mean forces of the last substep.
    force: Vec<f64>,
    /// The drives' dofs, and every dof of the kinematic trees they lie in (ascending): where
    /// `M⁻¹` of a drive's unit force, or of the robot's smooth force, is not zero.
    unit_dofs: Vec<usize>,
    tree_dofs: Vec<usize>,
    /// The columns of M⁻¹ at the drives' dofs (nv × n: row k for dof k).
    minv: Vec<f64>,
    /// The drives' response block W (n × n, row-major).
    w: Vec<f64>,
    /// Micro-step state: position, velocity, unconstrained acceleration, the explicit force
    /// of a pinching gripper drive (held over the micro-steps), force sum, position correction
    /// (n each).
    mq: Vec<f64>,
    mv: Vec<f64>,
    acc: Vec<f64>,
    micro_force: Vec<f64>,
    force_sum: Vec<f64>,
    correction: Vec<f64>,
    /// Per drive: the bodies its joint moves (gripper drives only; empty for arm drives).
    gripper_bodies: Vec<Vec<usize>>,
    /// Per body: whether it belongs to the robot.
    robot_body: Vec<bool>,
    /// Per dof: whether a drive acts on it.
    driven_dof: Vec<bool>,
    /// This substep's gripper contacts that their drive pushes into: (drive, other body).
    pushes: Vec<(usize, usize)>,
    /// Per drive: whether its gripper pinches an object against another part of the robot,
    /// and whether its gripper touches anything.
    pinching: Vec<bool>,
    touching: Vec<bool>,
    /// Per drive: whether an equality on an undriven dof (a linkage, a mimic) moves with it.
    linked: Vec<bool>,
    /// Penetration (m) beyond which a gripper link lets go of an object it has sunk into
    /// (see `Drives::release_deep_contacts`); `None`: never.
    release_depth: Option<f64>,
    /// This substep's released contacts (indices into the contact list) and geom pairs.
    released: Vec<usize>,
    /// (gripper drive, object body) pairs that let go this substep.
    released_pairs: Vec<(usize, usize)>,
    /// Per drive: for how many substeps in a row its gripper links have been deeper than the
    /// release depth in an object (see `Drives::release_deep_contacts`).
    deep_substeps: Vec<u32>,
    /// Per drive, this substep: its gripper links' contacts with objects, and the deepest.
    pinch_count: Vec<usize>,
    pinch_depth: Vec<f64>,
    /// The correction as an nv-vector and its product with M.
    cvec: Vec<f64>,
    mc: Vec<f64>,
    /// The constraint rows folded into `W` this substep (see [`Drives::fold_in_constraint_rows`]):
    /// their Jacobian rows (k × nv), M⁻¹ images (k × nv) and compliances `R` (k).
    fold_j: Vec<f64>,
    fold_y: Vec<f64>,
    fold_r: Vec<f64>,
    /// Most rows folded in (the buffers are sized for it; `Vec::clone` keeps lengths, not
    /// capacities, so the bound is stored).
    max_fold_rows: usize,
    /// Per row count k (index k, up to `max_fold_rows`): the dense matrices
    /// A = J M⁻¹ Jᵀ + R (k × k), Z = A⁻¹ (M⁻¹ Jᵀ at the drives) and M⁻¹ Jᵀ at the drives
    /// (k × n each), sized once so that the varying contact count never allocates.
    fold_a: Vec<DMatrix<f64>>,
    fold_z: Vec<DMatrix<f64>>,
    fold_yd: Vec<DMatrix<f64>>,
    /// Whether the last substep's arm took the pinch's kick (see
    /// [`Drives::report_velocities`]), and whether it can at all (an equality moves an
    /// undriven dof of the robot): then the flag is part of the saved state.
    kicking: bool,
    can_kick: bool,
    /// Whether every actuator of the model is one of these drives, so that the arm's
    /// unconstrained acceleration can be had from the smooth forces alone (see
    /// [`Drives::unconstrained_acceleration`]).
    drives_only: bool,
    /// The smooth forces with the drives off, and their acceleration (nv each).
    smooth_force: Vec<f64>,
    smooth_acc: Vec<f64>,
    /// The replica of PhysX's step that takes the physics steps in which the gripper pinches
    /// the object (opt-in, [`Drives::enable_pinch_replica`]).
    pinch: Option<Box<PinchReplica>>,
    /// Whether the model has geoms with a gap (a sphere object's speculative contacts, set
    /// with the pinch replica): only then do contacts lie apart.
    gap_contacts: bool,
}

impl Drives {
    /// Resolves `drives` (one force actuator per joint, named by
    /// [`super::desc::actuator_name`]) in `model`. `joints` are the robot's joints in
    /// ManiSkill order; `gripper` names the gripper joints. Errors name a missing joint or
    /// actuator.
    pub(crate) fn new(
        model: &Model,
        drives: &[Drive],
        joints: &[String],
        gripper: &[&str],
        release_depth: Option<f64>,
    ) -> Result<Drives, super::ControllerError> {
        let mut dofs = Vec::with_capacity(drives.len());
        for d in drives {
            let j = model.require_id(ObjType::Joint, &d.joint)?;
            let actuator =
                model.require_id(ObjType::Actuator, &super::desc::actuator_name(&d.joint))?;
            dofs.push(DriveDof {
                dof: model.jnt_dofadr()[j] as usize,
                qpos: model.jnt_qposadr()[j] as usize,
                actuator,
                kp: d.kp,
                kd: d.kd,
                force_limit: d.force_limit,
                arm: !gripper.contains(&d.joint.as_str()),
            });
        }
        let n = dofs.len();
        let nv = model.nv();
        let parent = model.body_parentid();
        // Whether body `b` lies in the subtree of body `root`.
        let in_subtree = |b: usize, root: usize| {
            let mut x = b;
            while x != 0 && x != root {
                x = parent[x] as usize;
            }
            x == root
        };
        // The subtree of a gripper joint's body: the links it moves.
        let gripper_bodies = dofs
            .iter()
            .map(|d| {
                if d.arm {
                    return Vec::new();
                }
                let root = model.dof_bodyid()[d.dof] as usize;
                (0..model.nbody())
                    .filter(|&b| in_subtree(b, root))
                    .collect()
            })
            .collect();
        // The robot: the subtree of the first joint's top-level ancestor.
        let robot_body = match dofs.first() {
            Some(d) => {
                let mut root = model.dof_bodyid()[d.dof] as usize;
                while parent[root] != 0 {
                    root = parent[root] as usize;
                }
                (0..model.nbody()).map(|b| in_subtree(b, root)).collect()
            }
            None => vec![false; model.nbody()],
        };
        let mut driven_dof = vec![false; nv];
        for d in &dofs {
            driven_dof[d.dof] = true;
        }
        // A gripper drive can move a linkage (and take the pinch's kick) only where the model
        // has equalities and the robot an undriven dof.
        let can_kick = model.neq() > 0
            && (0..nv).any(|k| !driven_dof[k] && robot_body[model.dof_bodyid()[k] as usize]);
        let unit_dofs: Vec<usize> = dofs.iter().map(|d| d.dof).collect();
        // The root dof of dof k's tree.
        let dof_parent = model.dof_parentid();
        let root = |mut k: usize| {
            while dof_parent[k] >= 0 {
                k = dof_parent[k] as usize;
            }
            k
        };
        let tree_dofs = (0..nv)
            .filter(|&k| unit_dofs.iter().any(|&u| root(u) == root(k)))
            .collect();
        let by_joint = joints
            .iter()
            .map(|j| drives.iter().position(|d| &d.joint == j))
            .collect();
        // Upper bound of the folded rows: equality rows (a connect has 3, a weld 6, a joint
        // 1) plus the gripper contacts'.
        let max_rows = 6 * model.neq() + MAX_GRIPPER_CONTACTS;
        let drives_only = model.nu() == n && model.na() == 0;
        Ok(Drives {
            by_joint,
            target_q: vec![0.0; n],
            target_v: vec![0.0; n],
            force: vec![0.0; n],
            unit_dofs,
            tree_dofs,
            minv: vec![0.0; n * nv],
            w: vec![0.0; n * n],
            mq: vec![0.0; n],
            mv: vec![0.0; n],
            acc: vec![0.0; n],
            micro_force: vec![0.0; n],
            force_sum: vec![0.0; n],
            correction: vec![0.0; n],
            gripper_bodies,
            robot_body,
            driven_dof,
            pushes: Vec::with_capacity(MAX_GRIPPER_CONTACTS),
            pinching: vec![false; n],
            touching: vec![false; n],
            linked: vec![false; n],
            release_depth,
            released: Vec::with_capacity(MAX_GRIPPER_CONTACTS),
            released_pairs: Vec::with_capacity(MAX_GRIPPER_CONTACTS),
            deep_substeps: vec![0; n],
            pinch_count: vec![0; n],
            pinch_depth: vec![0.0; n],
            cvec: vec![0.0; nv],
            mc: vec![0.0; nv],
            fold_j: Vec::with_capacity(max_rows * nv),
            fold_y: vec![0.0; max_rows * nv],
            fold_r: Vec::with_capacity(max_rows),
            max_fold_rows: max_rows,
            fold_a: (0..=max_rows).map(|k| DMatrix::zeros(k, k)).collect(),
            fold_z: (0..=max_rows).map(|k| DMatrix::zeros(k, n)).collect(),
            fold_yd: (0..=max_rows).map(|k| DMatrix::zeros(k, n)).collect(),
            kicking: false,
            can_kick,
            drives_only,
            smooth_force: vec![0.0; nv],
            smooth_acc: vec![0.0; nv],
            pinch: None,
            gap_contacts: false,
            dofs,
        })
    }

    /// Lets PhysX's step ([`super::tgs`]) take every physics step in which both jaws touch
    /// `object_body` (a free box or sphere, `object_geom`): `parts` are the jaws' convex parts, each
    /// with its body and jaw (0 or 1). Where `model`'s geoms have gaps (a sphere object's
    /// speculative contacts, given by the env), MuJoCo's step gives the contacts in them no
    /// force. Errors say what does not fit.
    pub fn enable_pinch_replica(
        &mut self,
        model: &Model,
        parts: Vec<JawPart>,
        object_body: usize,
        object_geom: usize,
    ) -> Result<(), String> {
        let drives = self
            .dofs
            .iter()
            .map(|d| {
                let local = self
                    .tree_dofs
                    .iter()
                    .position(|&k| k == d.dof)
                    .expect("a drive's dof lies in its tree");
                ReplicaDrive {
                    local,
                    kp: d.kp,
                    kd: d.kd,
                    force_limit: d.force_limit,
                }
            })
            .collect();
        let replica = PinchReplica::new(
            model,
            self.robot_body.clone(),
            &self.tree_dofs,
            drives,
            parts,
            object_body,
            object_geom,
        )?;
        self.pinch = Some(Box::new(replica));
        self.gap_contacts = model.geom_gap().iter().any(|&g| g > 0.0);
        Ok(())
    }

    /// The net contact force (world frame) the pinched object exerted on `body` in the last
    /// physics step, where the pinch replica took it (`None` otherwise).
    pub fn pinch_contact_force(&self, body: usize, dt: f64) -> Option<[f64; 3]> {
        self.pinch.as_ref().and_then(|p| p.contact_force(body, dt))
    }

    /// Whether the last physics step was taken by the pinch replica.
    pub fn pinch_replica_active(&self) -> bool {
        self.pinch.as_ref().is_some_and(|p| p.active())
    }

    /// Number of drives.
    pub fn len(&self) -> usize {
        self.dofs.len()
    }

    /// Whether there are no drives.
    pub fn is_empty(&self) -> bool {
        self.dofs.is_empty()
    }

    /// Sets the position and velocity target of drive `k`.
    pub fn set_target(&mut self, k: usize, q: f64, v: f64) {
        self.target_q[k] = q;
        self.target_v[k] = v;
    }

    /// Sets the targets of robot joint `k` (ManiSkill order); undriven joints are skipped.
    pub fn set_joint_target(&mut self, k: usize, q: f64, v: f64) {
        if let Some(d) = self.by_joint[k] {
            self.set_target(d, q, v);
        }
    }

    /// Position and velocity target of robot joint `k` (ManiSkill order); `None` for an
    /// undriven joint.
    pub fn joint_target(&self, k: usize) -> Option<(f64, f64)> {
        self.by_joint[k].map(|d| self.target(d))
    }

    /// Position and velocity target of drive `k`.
    pub fn target(&self, k: usize) -> (f64, f64) {
        (self.target_q[k], self.target_v[k])
    }

    /// Mean drive forces of the last substep.
    pub fn forces(&self) -> &[f64] {
        &self.force
    }

    /// Whether drive `i` kicks the arm this substep: a gripper drive that moves a linkage and
    /// pinches an object (see the module docs, "The pinch's kick").
    fn kicks(&self, i: usize) -> bool {
        self.pinching[i] && self.linked[i]
    }

    /// Writes into `qvel` (the robot's joint velocities, ManiSkill order, read from `data`)
    /// the velocities PhysX reports where they are not the motion: while the last substep's
    /// arm took the pinch's kick, each arm drive reports its force-free velocity
    /// `(kp (q* − q) + kd q̇*) / (kd + kp dt)` (dt a PhysX sub-step), the velocity its implicit
    /// drive brings the joint to before the gripper's kick takes it away again. PhysX's velocity
    /// pass keeps that velocity: measured on the WidowX AI holding the cube, ManiSkill
    /// reports `kp/kd (q* − q)` on a wrist that stands still (docs/physics.md, "The pinch's
    /// kick"). Elsewhere the reported velocity is the motion, as MuJoCo's.
    pub fn report_velocities(&self, data: &Data, qvel: &mut [f64]) {
        if !self.kicking {
            return;
        }
        let dt = data.model().timestep() / MICRO_STEPS as f64;
        let q = data.qpos();
        for (v, d) in qvel.iter_mut().zip(&self.by_joint) {
            if let Some(d) = *d {
                let dof = &self.dofs[d];
                if dof.arm {
                    *v = (dof.kp * (self.target_q[d] - q[dof.qpos]) + dof.kd * self.target_v[d])
                        / (dof.kd + dof.kp * dt);
                }
            }
        }
    }

    /// Computes the drive forces for the coming substep of length `h` and writes them as
    /// the actuator controls. Call after [`Data::step1`] (which factorises M and builds the
    /// constraint rows) and before [`Data::step2`]. No allocation.
    pub fn apply(&mut self, data: &mut Data, h: f64) {
        let n = self.dofs.len();
        if n == 0 {
            return;
        }
        let nv = data.model().nv();
        data.solve_m_units(&mut self.minv, &self.unit_dofs, &self.tree_dofs);
        for (i, di) in self.dofs.iter().enumerate() {
            self.w[i * n..(i + 1) * n].copy_from_slice(&self.minv[di.dof * n..(di.dof + 1) * n]);
        }
        self.gather_constraint_rows(data, nv);
        self.fold_in_constraint_rows(data, nv);
        self.unconstrained_acceleration(data, true);
        let (qpos, qvel) = (data.qpos(), data.qvel());
        for (i, d) in self.dofs.iter().enumerate() {
            self.mq[i] = qpos[d.qpos];
            self.mv[i] = qvel[d.dof];
            self.acc[i] = if d.arm { self.smooth_acc[d.dof] } else { 0.0 };
        }
        let dt = h / MICRO_STEPS as f64;
        self.force_sum.fill(0.0);
        // A gripper pinching an object against the rest of the robot (the opposite finger or
        // a fixed jaw) squeezes it: the object cannot give way, so the drive acts with the
        // force PhysX's implicit drive has for a blocked joint (zero response), explicitly;
        // the damping is capped so that it cannot reverse a still-moving finger within the
        // substep (its free inertia is 1 / W_ii).
        for (i, d) in self.dofs.iter().enumerate() {
            self.micro_force[i] = if self.pinching[i] {
                let kd = d.kd.min(1.0 / (h * self.minv[d.dof * n + i]));
                (d.kp * (self.target_q[i] - qpos[d.qpos]) + d.kd * self.target_v[i]
                    - kd * qvel[d.dof])
                    .clamp(-d.force_limit, d.force_limit)
            } else {
                0.0
            };
        }
        // PhysX's position iterations: one pass over the drives in joint order, each drive's
        // implicit impulse computed from the velocity that the passes before it left
        // (sequential impulses, not a converged coupled solve: where two joints' axes are
        // nearly parallel, as the Panda's joints 1 and 3 often are, the two differ by a third
        // of joint 1's motion in a step).
        for _ in 0..MICRO_STEPS {
            for i in 0..n {
                self.mv[i] += dt * self.acc[i];
            }
            for (i, d) in self.dofs.iter().enumerate() {
                let row = &self.w[i * n..(i + 1) * n];
                let f = if self.pinching[i] {
                    self.micro_force[i]
                } else {
                    let g = dt * d.kp + d.kd;
                    let c = d.kp * (self.target_q[i] - self.mq[i]) + d.kd * self.target_v[i];
                    // PhysX clamps the impulse accumulated over the step's iterations to
                    // F·h, not each iteration's: a saturated drive spends more of it early.
                    let cap = d.force_limit * MICRO_STEPS as f64;
                    ((c - g * self.mv[i]) / (1.0 + dt * g * row[i]))
                        .clamp(-cap - self.force_sum[i], cap - self.force_sum[i])
                };
                // W is symmetric: column i is row i. The force of a pinching drive that
                // moves a linkage does not reach the arm drives (see the module docs, "The
                // pinch's kick").
                let kicks = self.kicks(i);
                for ((v, w), dk) in self.mv.iter_mut().zip(row).zip(&self.dofs) {
                    if !(kicks && dk.arm) {
                        *v += dt * w * f;
                    }
                }
                self.force_sum[i] += f;
            }
            for i in 0..n {
                self.mq[i] += dt * self.mv[i];
            }
        }
        for (i, d) in self.dofs.iter().enumerate() {
            self.force[i] = self.force_sum[i] / MICRO_STEPS as f64;
            self.correction[i] = if d.arm || !(self.touching[i] || self.linked[i]) {
                self.mq[i] - (qpos[d.qpos] + h * self.mv[i])
            } else {
                0.0
            };
        }
        let ctrl = data.ctrl_mut();
        for (d, &f) in self.dofs.iter().zip(&self.force) {
            ctrl[d.actuator] = f;
        }
        // The position correction travels as velocity: a generalised force M c / h² moves
        // the arm by c more during the substep (and whatever it holds with it, through the
        // contacts), and `step` takes the extra c / h off the velocity afterwards.
        self.cvec.fill(0.0);
        for (d, &c) in self.dofs.iter().zip(&self.correction) {
            self.cvec[d.dof] = c;
        }
        // The pinch's kick: the acceleration the force of a pinching gripper drive that moves
        // a linkage gives the arm through the articulation, travelling with the correction as
        // `M a`.
        self.kicking = (0..n).any(|i| self.kicks(i));
        if self.kicking {
            for (j, dj) in self.dofs.iter().enumerate() {
                if !dj.arm {
                    continue;
                }
                let row = &self.w[j * n..(j + 1) * n];
                let kick: f64 = (0..n)
                    .filter(|&i| self.kicks(i))
                    .map(|i| row[i] * self.micro_force[i])
                    .sum();
                self.cvec[dj.dof] += kick * h * h;
            }
        }
        data.mul_m(&mut self.mc, &self.cvec);
        for (f, mc) in data.qfrc_applied_mut().iter_mut().zip(&self.mc) {
            *f = mc / (h * h);
        }
    }

    /// The robot's unconstrained acceleration (Coriolis, passive forces) with the drives
    /// switched off, at the drives' kinematic trees' dofs (the other entries are not
    /// written): what MuJoCo's
    /// `mj_fwdActuation` and `mj_fwdAcceleration` give with the drives' controls and
    /// `qfrc_applied` at zero. Call after [`Data::step1`]; it may leave the controls and
    /// `qfrc_applied` at zero, which [`Drives::apply`] then overwrites.
    ///
    /// With `shortcut`, where every actuator is a drive and no robot body carries an applied
    /// wrench, it skips those two calls (a twentieth of a Fetch substep): the robot's smooth
    /// force is then `qfrc_passive − qfrc_bias`, plus MuJoCo's zero actuator and applied
    /// forces (the `+ 0.0`, which turns a −0 into +0 as MuJoCo's sums do), and the props'
    /// wrenches reach only their own kinematic trees, so `M⁻¹` of that force at the robot's
    /// dofs is MuJoCo's `qacc_smooth` bit for bit.
    pub(crate) fn unconstrained_acceleration(&mut self, data: &mut Data, shortcut: bool) -> &[f64] {
        let xfrc = data.xfrc_applied();
        let wrenched = xfrc
            .chunks_exact(6)
            .zip(&self.robot_body)
            .any(|(wrench, &robot)| robot && wrench.iter().any(|&x| x != 0.0));
        if shortcut && self.drives_only && !wrenched {
            let (passive, bias) = (data.qfrc_passive(), data.qfrc_bias());
            for &k in &self.tree_dofs {
                self.smooth_force[k] = passive[k] - bias[k] + 0.0;
            }
            data.solve_m(&mut self.smooth_acc, &self.smooth_force, 1);
        } else {
            let ctrl = data.ctrl_mut();
            for d in &self.dofs {
                ctrl[d.actuator] = 0.0;
            }
            data.qfrc_applied_mut().fill(0.0);
            data.smooth_acceleration();
            self.smooth_acc.copy_from_slice(data.qacc_smooth());
        }
        &self.smooth_acc
    }

    /// Whether [`Drives::unconstrained_acceleration`] can take its shortcut: every actuator
    /// of the model is one of these drives.
    #[cfg(test)]
    pub(crate) fn drives_only(&self) -> bool {
        self.drives_only
    }

    /// The dofs of the drives' kinematic trees (ascending).
    #[cfg(test)]
    pub(crate) fn tree_dofs(&self) -> &[usize] {
        &self.tree_dofs
    }

    /// Collects the constraint rows [`Drives::fold_in_constraint_rows`] folds into `W`,
    /// with their compliance `R`:
    /// * the equality rows that move an undriven dof (equalities whose every dof has a drive
    ///   of its own, like the Panda's finger mimic, are left to the drives), and
    /// * the contact normals of gripper links that their drive pushes into (the normal
    ///   velocity would fall under the drive's force), taken as bilateral for the substep:
    ///   a closing finger then feels what it pushes, a free cube or the opposite finger.
    ///
    /// On the way it marks the drives that move a linkage (`linked`), whose gripper touches
    /// anything (`touching`) and whose gripper pinches an object against the rest of the
    /// robot (`pinching`).
    fn gather_constraint_rows(&mut self, data: &Data, nv: usize) {
        let max_rows = self.max_fold_rows;
        self.fold_j.clear();
        self.fold_r.clear();
        self.linked.fill(false);
        let ne_all = data.ne();
        if let Some(jac) = data.equality_jacobian() {
            let compliance = data.efc_r(ne_all);
            for r in 0..ne_all {
                let row = &jac[r * nv..(r + 1) * nv];
                let undriven = row
                    .iter()
                    .enumerate()
                    .any(|(k, &x)| x != 0.0 && !self.driven_dof[k]);
                if undriven && self.fold_r.len() < max_rows {
                    self.fold_j.extend_from_slice(row);
                    self.fold_r.push(compliance[r]);
                    for (d, linked) in self.dofs.iter().zip(&mut self.linked) {
                        *linked |= row[d.dof] != 0.0;
                    }
                }
            }
        }
        let geom_body = data.model().geom_bodyid();
        let qpos = data.qpos();
        let compliance = data.efc_r(data.nefc());
        self.pushes.clear();
        self.touching.fill(false);
        for c in 0..data.ncon() {
            if self.fold_r.len() == max_rows {
                break;
            }
            if self.released.contains(&c) || (self.gap_contacts && separated(data, c)) {
                continue;
            }
            let (g1, g2) = data.contact_geoms(c);
            let (b1, b2) = (geom_body[g1] as usize, geom_body[g2] as usize);
            let Some((row0, rows)) = data.contact_rows(c) else {
                continue;
            };
            let Some(jac) = data.constraint_rows(row0, rows) else {
                continue;
            };
            // The normal row: the mean of the first pyramid edge pair, or the first row.
            let normal = |k: usize| {
                if rows > 1 {
                    0.5 * (jac[k] + jac[nv + k])
                } else {
                    jac[k]
                }
            };
            let mut pushed = false;
            for (i, (d, bodies)) in self.dofs.iter().zip(&self.gripper_bodies).enumerate() {
                let other = if bodies.contains(&b1) {
                    b2
                } else if bodies.contains(&b2) {
                    b1
                } else {
                    continue;
                };
                self.touching[i] = true;
                // The drive's intent: its spring and target velocity, not its damping.
                let push = d.kp * (self.target_q[i] - qpos[d.qpos]) + d.kd * self.target_v[i];
                if normal(d.dof) * push < 0.0 {
                    pushed = true;
                    if !self.robot_body[other] && self.pushes.len() < MAX_GRIPPER_CONTACTS {
                        self.pushes.push((i, other));
                    }
                }
            }
            if pushed {
                self.fold_j.extend((0..nv).map(normal));
                self.fold_r.push(compliance[row0]);
            }
        }
        // Pinching: an object a gripper pushes also touches the robot outside that gripper.
        self.pinching.fill(false);
        for c in 0..data.ncon() {
            if self.released.contains(&c) || (self.gap_contacts && separated(data, c)) {
                continue;
            }
            let (g1, g2) = data.contact_geoms(c);
            let (b1, b2) = (geom_body[g1] as usize, geom_body[g2] as usize);
            let (robot, object) = match (self.robot_body[b1], self.robot_body[b2]) {
                (true, false) => (b1, b2),
                (false, true) => (b2, b1),
                _ => continue,
            };
            for &(i, o) in &self.pushes {
                if o == object && !self.gripper_bodies[i].contains(&robot) {
                    self.pinching[i] = true;
                }
            }
        }
    }

    /// Lets go of objects that a gripper has sunk into deeper than the release depth: every
    /// contact between the links the gripper joint moves and that object gets no force this
    /// substep (nor a place in the drive's response). PhysX's SO100 jaw sinks into a cube it
    /// squeezes and follows its target; at about 3 mm (jaw −0.93 rad on the 25 mm cube) it
    /// passes through and the cube drops (docs/outcome-physics.md). The depth must hold for
    /// [`RELEASE_SUBSTEPS`] face-on substeps in a row: MuJoCo's box–box collider reports,
    /// in some substeps, a three-point edge manifold of the same pinch with about twice the
    /// depth (2.6 mm face-on, 5.5 mm as an edge, at a jaw target of −0.9), which would pass
    /// for a pass-through; such substeps count neither way. Only objects (not the robot)
    /// are let go. No allocation: at most [`MAX_GRIPPER_CONTACTS`] contacts a substep.
    fn release_deep_contacts(&mut self, data: &mut Data) {
        self.released.clear();
        self.released_pairs.clear();
        let Some(depth) = self.release_depth else {
            return;
        };
        // Per gripper drive: its links' contacts with objects, and the deepest of them.
        self.pinch_count.fill(0);
        self.pinch_depth.fill(0.0);
        for c in 0..data.ncon() {
            let k = data.contact(c);
            if k.excluded {
                continue;
            }
            let geom_body = data.model().geom_bodyid();
            let (b1, b2) = (geom_body[k.geom1] as usize, geom_body[k.geom2] as usize);
            for (i, bodies) in self.gripper_bodies.iter().enumerate() {
                let object = if bodies.contains(&b1) && !self.robot_body[b2] {
                    b2
                } else if bodies.contains(&b2) && !self.robot_body[b1] {
                    b1
                } else {
                    continue;
                };
                self.pinch_count[i] += 1;
                self.pinch_depth[i] = self.pinch_depth[i].max(-k.dist);
                if self.released_pairs.len() < MAX_GRIPPER_CONTACTS
                    && !self.released_pairs.contains(&(i, object))
                {
                    self.released_pairs.push((i, object));
                }
            }
        }
        // A face-on pinch (at least FACE_CONTACTS points) counts for or against a release;
        // MuJoCo's edge manifolds of the same pinch (fewer points, with an exaggerated depth)
        // count for neither.
        for (i, substeps) in self.deep_substeps.iter_mut().enumerate() {
            if self.pinch_count[i] >= FACE_CONTACTS {
                *substeps = if self.pinch_depth[i] > depth {
                    substeps.saturating_add(1)
                } else {
                    0
                };
            } else if self.pinch_count[i] == 0 {
                *substeps = 0;
            }
        }
        let substeps = &self.deep_substeps;
        self.released_pairs
            .retain(|&(i, _)| substeps[i] >= RELEASE_SUBSTEPS);
        if self.released_pairs.is_empty() {
            return;
        }
        // ... let go: every contact between that gripper's links and that object.
        for c in 0..data.ncon() {
            if self.released.len() == MAX_GRIPPER_CONTACTS {
                break;
            }
            if self.gap_contacts && separated(data, c) {
                continue;
            }
            let (g1, g2) = data.contact_geoms(c);
            let geom_body = data.model().geom_bodyid();
            let (b1, b2) = (geom_body[g1] as usize, geom_body[g2] as usize);
            let hit = self.released_pairs.iter().any(|&(i, o)| {
                let bodies = &self.gripper_bodies[i];
                (o == b2 && bodies.contains(&b1)) || (o == b1 && bodies.contains(&b2))
            });
            if hit && data.release_contact(c) {
                self.released.push(c);
            }
        }
    }

    /// Restricts `W` to the motions the gathered rows allow, with MuJoCo's compliance `R` of
    /// those (soft) constraints: `W − (J M⁻¹)ᵀ (J M⁻¹ Jᵀ + R)⁻¹ (J M⁻¹)` at the drives.
    fn fold_in_constraint_rows(&mut self, data: &mut Data, nv: usize) {
        let n = self.dofs.len();
        let k = self.fold_r.len();
        if k == 0 {
            return;
        }
        data.solve_m(&mut self.fold_y, &self.fold_j, k);
        let (a, z, yd) = (
            &mut self.fold_a[k],
            &mut self.fold_z[k],
            &mut self.fold_yd[k],
        );
        for r in 0..k {
            for c in 0..k {
                a[(r, c)] = (0..nv)
                    .map(|x| self.fold_j[r * nv + x] * self.fold_y[c * nv + x])
                    .sum::<f64>();
            }
            a[(r, r)] += self.fold_r[r];
            for (c, d) in self.dofs.iter().enumerate() {
                yd[(r, c)] = self.fold_y[r * nv + d.dof];
            }
        }
        z.copy_from(yd);
        // In place: `cholesky` takes the buffer and `unpack` gives it back.
        let owned = std::mem::replace(a, DMatrix::zeros(0, 0));
        match owned.cholesky() {
            Some(chol) => {
                chol.solve_mut(z);
                *a = chol.unpack();
            }
            // Not positive definite (R > 0 rules it out): keep the free response. The
            // buffer is rebuilt at its size so that the next substep finds it again.
            None => {
                *a = DMatrix::zeros(k, k);
                return;
            }
        }
        for i in 0..n {
            for j in 0..n {
                let fold: f64 = (0..k).map(|r| yd[(r, i)] * z[(r, j)]).sum();
                self.w[i * n + j] -= fold;
            }
        }
    }

    /// One physics substep with the drives: `mj_step1`, [`Drives::apply`], `mj_step2`,
    /// then the arm joints' position correction.
    pub fn step(&mut self, data: &mut Data) {
        let h = data.model().timestep();
        data.step1();
        if let Some(p) = self.pinch.as_deref_mut() {
            if p.pinches(data) {
                p.step(data, &self.target_q, &self.target_v);
            } else {
                p.idle();
            }
        }
        self.release_deep_contacts(data);
        if self.gap_contacts {
            // A sphere's speculative contacts (its margin, `CONTACT_OFFSET`) are the replica's;
            // MuJoCo's step gives them no force.
            for c in 0..data.ncon() {
                if separated(data, c) {
                    data.release_contact(c);
                }
            }
        }
        self.apply(data, h);
        data.step2();
        let v = data.qvel_mut();
        for (d, c) in self.dofs.iter().zip(&self.correction) {
            v[d.dof] -= c / h;
            // PhysX's per-axis speed limit of articulation joints (`maxJointVelocity`).
            v[d.dof] = v[d.dof].clamp(-MAX_JOINT_VELOCITY, MAX_JOINT_VELOCITY);
        }
        // The pinch replica's step replaces MuJoCo's for the robot and the object.
        if let Some(p) = self.pinch.as_deref() {
            p.write(data);
        }
    }
}

/// Whether contact `c` is one of a sphere object's speculative contacts, which MuJoCo reports
/// in the sphere's gap when the pinch replica is on (never without gaps).
fn separated(data: &Data, c: usize) -> bool {
    data.contact(c).in_gap
}
