//! Joint drives: PhysX's articulation drive law, applied at every physics substep.
//!
//! ManiSkill drives every controlled joint with a PhysX force drive: stiffness `kp`, damping
//! `kd`, force limit `F`, position target `q*` and velocity target `q̇*`. PhysX integrates
//! the drive *implicitly* — the force is computed against the joint velocity at the end of
//! the step — and clamps the whole force, damping included (`computeImplicitDriveParams
//! ForceDrive` / `computeDriveImpulse` in PhysX's `DyCpuGpuArticulation.h`):
//!
//! ```text
//! F = clamp( kp (q* − q − h q̇') + kd (q̇* − q̇'), −F_max, F_max ),   q̇' = q̇ + h M⁻¹ F
//! ```
//!
//! [`Drives::apply`] solves this for all drives of a robot at once (projected Gauss–Seidel
//! on the joint-space response `M⁻¹`, which couples the drives of one articulation; the
//! first sweep is exactly PhysX's per-dof formula with the articulated unit response) and
//! writes the forces as the controls of force actuators (gain 1, no bias). MuJoCo then
//! integrates with its explicit Euler step while contacts, joint limits and equality
//! constraints stay implicit in its constraint solver. Because the drive is implicit in its
//! own terms, stiff drives are stable at PhysX's 0.01 s step without added armature.
use crate::mjcf::Drive;
use crate::mujoco::{Data, Model, ObjType};

/// Gauss–Seidel sweeps over the coupled drive equations per substep.
pub const SWEEPS: usize = 4;

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
}

/// The drives of one robot: targets plus the force law.
#[derive(Debug, Clone)]
pub struct Drives {
    dofs: Vec<DriveDof>,
    /// Position target per drive.
    target_q: Vec<f64>,
    /// Velocity target per drive.
    target_v: Vec<f64>,
    /// Forces of the last substep.
    force: Vec<f64>,
    /// Scratch: unit vectors (n × nv) and their M⁻¹ images (n × nv).
    unit: Vec<f64>,
    minv: Vec<f64>,
    /// Scratch: the drives' block of M⁻¹ (n × n, row-major).
    w: Vec<f64>,
}

impl Drives {
    /// Resolves `drives` (one force actuator per joint, named by
    /// [`crate::mjcf::actuator_name`]) in `model`. Errors name a missing joint or actuator.
    pub fn new(model: &Model, drives: &[Drive]) -> Result<Drives, String> {
        let mut dofs = Vec::with_capacity(drives.len());
        for d in drives {
            let j = model
                .require_id(ObjType::Joint, &d.joint)
                .map_err(|e| e.to_string())?;
            let actuator = model
                .require_id(ObjType::Actuator, &crate::mjcf::actuator_name(&d.joint))
                .map_err(|e| e.to_string())?;
            dofs.push(DriveDof {
                dof: model.jnt_dofadr()[j] as usize,
                qpos: model.jnt_qposadr()[j] as usize,
                actuator,
                kp: d.kp,
                kd: d.kd,
                force_limit: d.force_limit,
            });
        }
        let n = dofs.len();
        let nv = model.nv();
        let mut unit = vec![0.0; n * nv];
        for (k, d) in dofs.iter().enumerate() {
            unit[k * nv + d.dof] = 1.0;
        }
        Ok(Drives {
            dofs,
            target_q: vec![0.0; n],
            target_v: vec![0.0; n],
            force: vec![0.0; n],
            unit,
            minv: vec![0.0; n * nv],
            w: vec![0.0; n * n],
        })
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

    /// Position and velocity target of drive `k`.
    pub fn target(&self, k: usize) -> (f64, f64) {
        (self.target_q[k], self.target_v[k])
    }

    /// Forces applied in the last substep.
    pub fn forces(&self) -> &[f64] {
        &self.force
    }

    /// Computes the drive forces for the coming substep of length `h` and writes them as
    /// the actuator controls. Call between [`Data::step1`] (which factorises M) and
    /// [`Data::step2`]. No allocation.
    pub fn apply(&mut self, data: &mut Data, h: f64) {
        let n = self.dofs.len();
        if n == 0 {
            return;
        }
        let nv = data.model().nv();
        data.solve_m(&mut self.minv, &self.unit, n);
        for (i, di) in self.dofs.iter().enumerate() {
            for j in 0..n {
                self.w[i * n + j] = self.minv[j * nv + di.dof];
            }
        }
        let (qpos, qvel) = (data.qpos(), data.qvel());
        self.force.fill(0.0);
        for _ in 0..SWEEPS {
            for (i, d) in self.dofs.iter().enumerate() {
                let g = h * d.kp + d.kd;
                let c = d.kp * (self.target_q[i] - qpos[d.qpos]) + d.kd * self.target_v[i];
                let row = &self.w[i * n..(i + 1) * n];
                let v1 =
                    qvel[d.dof] + h * row.iter().zip(&self.force).map(|(w, f)| w * f).sum::<f64>();
                let residual = c - g * v1 - self.force[i];
                let f = self.force[i] + residual / (1.0 + h * g * row[i]);
                self.force[i] = f.clamp(-d.force_limit, d.force_limit);
            }
        }
        let ctrl = data.ctrl_mut();
        for (d, &f) in self.dofs.iter().zip(&self.force) {
            ctrl[d.actuator] = f;
        }
    }

    /// One physics substep with the drives: `mj_step1`, [`Drives::apply`], `mj_step2`.
    pub fn step(&mut self, data: &mut Data) {
        let h = data.model().timestep();
        data.step1();
        self.apply(data, h);
        data.step2();
    }

    /// Appends the targets (position then velocity, per drive) to `out`.
    pub fn save(&self, out: &mut Vec<f64>) {
        out.extend_from_slice(&self.target_q);
        out.extend_from_slice(&self.target_v);
    }

    /// Number of values [`Drives::save`] writes.
    pub fn save_len(&self) -> usize {
        2 * self.dofs.len()
    }

    /// Restores what [`Drives::save`] wrote.
    pub fn load(&mut self, s: &[f64]) {
        let n = self.dofs.len();
        self.target_q.copy_from_slice(&s[..n]);
        self.target_v.copy_from_slice(&s[n..2 * n]);
    }
}
