//! PegInsertionSide-v1 (docs/tasks.md §11): pick up a peg lying on the table and push its
//! orange end sideways into the hole of a box.
//!
//! The panda_wristcam's task. Its shapes change every episode, as upstream rebuilds its scene
//! at every reset (`reconfiguration_freq = 1` for one env): the peg's half length and radius
//! and the hole's offset are drawn from the episode's numpy stream ([`PegGeometry::draw`]),
//! and the box's half length equals the peg's. The env writes them into the compiled model
//! in place ([`crate::mujoco::Model::set_box_geom`]).
//!
//! The peg is one box along its local x (ManiSkill's two visual halves: the white tail at −x,
//! the orange head at +x). The box with the hole is kinematic: four boxes around a square hole
//! along its local x, 3 mm wider than the peg ([`CLEARANCE`]).
//!
//! Upstream quirks kept for parity: `info` holds the head's position in the hole's frame
//! (`peg_head_pos_at_hole`, three entries here: `[0]`, `[1]`, `[2]`), and no grasp flag,
//! though the reward checks the grasp, with a tighter angle than the robot's own check
//! ([`GRASP_MAX_ANGLE`]).
use std::f64::consts::FRAC_PI_2;

use nalgebra::{UnitQuaternion, Vector3};

use super::place_sphere::FINGER_PATCH_RADIUS;
use super::push_cube::ABSENT_GRASP_FLAG;
use super::{
    add_cameras, body_id, closeness, free_joint_qpos, set_free_pose, set_mocap_pose,
    tabletop_cameras, yaw_quat_f32, CameraDef, ObsWriter, Task, TaskCtx,
};
use crate::mjcf::props::{box_with_hole, peg_inertia, Rgba};
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, GeomId, MjError, Model};
use crate::rng::{NumpyRandomState, TorchGenerator};

// ---- constants (docs/tasks.md §11) ----------------------------------------------------------
/// Maximum dense reward (the value given on success).
pub const MAX_REWARD: f64 = 10.0;
/// Range of the peg's half length (m), drawn per episode; the box is as long.
pub const HALF_LENGTH_RANGE: (f64, f64) = (0.085, 0.125);
/// Range of the peg's radius (half width, m), drawn per episode.
pub const RADIUS_RANGE: (f64, f64) = (0.015, 0.025);
/// How much wider the hole's half width is than the peg's radius (m).
pub const CLEARANCE: f64 = 0.003;
/// The peg's tail (−x half): `hex2rgba("#EDF6F9")`, gamma-corrected as upstream.
pub const PEG_TAIL_RGBA: Rgba = [0.851252, 0.923993, 0.948965, 1.0];
/// The peg's head (+x half): `hex2rgba("#EC7357")`.
pub const PEG_HEAD_RGBA: Rgba = [0.84337, 0.173439, 0.093876, 1.0];
/// The box with the hole: `hex2rgba("#FFD289")`.
pub const BOX_RGBA: Rgba = [1.0, 0.65237, 0.254916, 1.0];
/// The peg's build position (before the first reset), as upstream.
const PEG_BUILD_POS: [f64; 3] = [0.0, 0.0, 0.1];
/// The box's build position, as upstream.
const BOX_BUILD_POS: [f64; 3] = [0.0, 1.0, 0.1];
/// The shapes the scene is built with before the first reset draws any (the ranges' middles).
const BUILD_GEOMETRY: PegGeometry = PegGeometry {
    half_length: 0.105,
    radius: 0.02,
    center: [0.0, 0.0],
};
/// The peg's spawn square: x in [−0.1, 0.1], y in [−0.3, 0] (float32 bounds, as upstream).
const PEG_SPAWN: ([f32; 2], [f32; 2]) = ([-0.1, -0.3], [0.1, 0.0]);
/// The box's spawn square: x in [−0.05, 0.05], y in [0.2, 0.4].
const BOX_SPAWN: ([f32; 2], [f32; 2]) = ([-0.05, 0.2], [0.05, 0.4]);
/// Half width of the peg's yaw range about π/2 (rad).
const PEG_YAW_HALF_RANGE: f64 = std::f64::consts::PI / 3.0;
/// Half width of the box's yaw range about π/2 (rad).
const BOX_YAW_HALF_RANGE: f64 = std::f64::consts::PI / 8.0;
/// The task's own robot pose: the panda_wristcam's rest, with a second noise draw.
const ROBOT_QPOS: [f64; 9] = crate::robots::panda_wristcam::REST;
/// Standard deviation of that draw, fixed by the task (rad).
const ROBOT_QPOS_NOISE: f64 = 0.02;
/// Success: the head at most this far (m) on the outer side of the hole's centre plane.
pub const INSERTED_DEPTH: f64 = 0.015;
/// The grasp check of the reward: at most this angle (degrees) between a finger's opening
/// direction and its contact force ("not grasping the peg at an awkward pose").
pub const GRASP_MAX_ANGLE: f64 = 20.0;
/// The reward's grasp target: this far behind the peg's centre along its axis (m), "for the
/// gripper's width with a bit more leeway".
const GRASP_TARGET_OFFSET: f64 = -0.06;
/// Scale of the reaching term `1 − tanh(4 d)`.
const REACH_SCALE: f64 = 4.0;
/// Weight of the pre-insertion term.
const PRE_INSERTION_WEIGHT: f64 = 3.0;
/// Weights of the two ends' mean and larger distance from the hole's axis in the
/// pre-insertion term `1 − tanh(0.5·(a + b) + 4.5·max(a, b))`.
const LINE_UP_MEAN: f64 = 0.5;
const LINE_UP_MAX: f64 = 4.5;
/// Weight of the insertion term.
const INSERTION_WEIGHT: f64 = 5.0;
/// Both ends within this of the hole's axis (m): lined up for insertion.
const PRE_INSERTED_DIST: f64 = 0.01;

/// The `info` keys: `success`, then `peg_head_pos_at_hole` by component.
const INFO_KEYS: [&str; 4] = [
    "success",
    "peg_head_pos_at_hole[0]",
    "peg_head_pos_at_hole[1]",
    "peg_head_pos_at_hole[2]",
];

/// One episode's shapes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PegGeometry {
    /// The peg's half length along its axis (m), also the box's half length.
    pub half_length: f64,
    /// The peg's radius (half width, m).
    pub radius: f64,
    /// The hole's offset (y, z) from the box's centre, in the box's frame (m).
    pub center: [f64; 2],
}

impl PegGeometry {
    /// Upstream's draws in `_load_scene`, in order: `uniform(0.085, 0.125)`,
    /// `uniform(0.015, 0.025)`, then `0.5·(length − radius)·uniform(−1, 1, size=2)`.
    pub fn draw(numpy: &mut NumpyRandomState) -> PegGeometry {
        let half_length = numpy.uniform(HALF_LENGTH_RANGE.0, HALF_LENGTH_RANGE.1);
        let radius = numpy.uniform(RADIUS_RANGE.0, RADIUS_RANGE.1);
        let scale = 0.5 * (half_length - radius);
        let center = [
            scale * numpy.uniform(-1.0, 1.0),
            scale * numpy.uniform(-1.0, 1.0),
        ];
        PegGeometry {
            half_length,
            radius,
            center,
        }
    }

    /// The hole's half width (the peg's radius plus [`CLEARANCE`]).
    pub fn hole_radius(&self) -> f64 {
        self.radius + CLEARANCE
    }

    /// The four boxes of the box with the hole: the hole's half width, the box's half width
    /// and half length the peg's half length.
    pub fn box_walls(&self) -> [([f64; 3], [f64; 3]); 4] {
        let l = self.half_length;
        box_with_hole(self.hole_radius(), l, l, self.center)
    }

    /// As numbers, for a saved state.
    fn to_vec(self) -> Vec<f64> {
        vec![
            self.half_length,
            self.radius,
            self.center[0],
            self.center[1],
        ]
    }

    /// From numbers that [`PegGeometry::to_vec`] gave; an error names a wrong length or a
    /// value outside the ranges upstream draws from.
    fn from_slice(v: &[f64]) -> Result<PegGeometry, String> {
        let &[half_length, radius, cy, cz] = v else {
            return Err(format!(
                "PegInsertionSide-v1's shapes are 4 values (half length, radius, hole y, hole z), got {}",
                v.len()
            ));
        };
        let within = |x: f64, (lo, hi): (f64, f64)| x.is_finite() && x >= lo && x <= hi;
        let scale = 0.5 * (half_length - radius);
        let checks = [
            ("half length", half_length, HALF_LENGTH_RANGE),
            ("radius", radius, RADIUS_RANGE),
            ("hole y", cy, (-scale, scale)),
            ("hole z", cz, (-scale, scale)),
        ];
        for (name, x, range) in checks {
            if !within(x, range) {
                return Err(format!(
                    "the peg's {name} {x} is outside [{}, {}]",
                    range.0, range.1
                ));
            }
        }
        Ok(PegGeometry {
            half_length,
            radius,
            center: [cy, cz],
        })
    }
}

/// A pose as position and rotation.
type Frame = (Vector3<f64>, UnitQuaternion<f64>);

/// The rotation of a raw (w, x, y, z) quaternion.
fn rotation(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// `pose · Pose(p=offset)`: a point fixed in a frame.
fn offset(frame: &Frame, offset: [f64; 3]) -> Frame {
    (frame.0 + frame.1 * Vector3::from(offset), frame.1)
}

/// `(frame.inv() · point)`: a point in a frame's coordinates.
fn local(frame: &Frame, point: &Vector3<f64>) -> Vector3<f64> {
    frame.1.inverse_transform_vector(&(point - frame.0))
}

/// quat(euler XYZ (0, 0, yaw)) for `yaw = u·(2·half) + (π/2 − half)`, upstream's
/// `random_quaternions(lock_x, lock_y, bounds)` in float32 (it draws `rand(3)`; only the
/// third value is used).
fn random_yaw(torch: &mut TorchGenerator, half: f64) -> [f64; 4] {
    let mut e = [0f32; 3];
    torch.fill_rand(&mut e);
    // `rand · (bounds[1] − bounds[0]) + bounds[0]`, the bounds' difference taken in double.
    let (low, high) = (FRAC_PI_2 - half, FRAC_PI_2 + half);
    yaw_quat_f32(e[2] * (high - low) as f32 + low as f32)
}

/// `uniform(low, high, size=(1, 2))` in float32: `rand(2)·(high − low) + low`.
fn random_xy(torch: &mut TorchGenerator, (low, high): ([f32; 2], [f32; 2])) -> [f64; 2] {
    let mut u = [0f32; 2];
    torch.fill_rand(&mut u);
    [0, 1].map(|k| (u[k] * (high[k] - low[k]) + low[k]) as f64)
}

/// PegInsertionSide-v1's `evaluate()`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PegInsertionSideEval {
    /// The peg's head is in the hole, at most [`INSERTED_DEPTH`] short of its centre.
    pub success: bool,
    /// The head's position in the hole's frame (x along the hole, towards the box's far side).
    pub peg_head_pos_at_hole: [f64; 3],
}

/// PegInsertionSide-v1.
#[derive(Debug, Clone)]
pub struct PegInsertionSide {
    geometry: PegGeometry,
    peg: BodyId,
    peg_qadr: usize,
    peg_geom: GeomId,
    box_body: BodyId,
    box_geoms: [GeomId; 4],
}

impl Default for PegInsertionSide {
    fn default() -> Self {
        PegInsertionSide {
            geometry: BUILD_GEOMETRY,
            peg: BodyId::from_index(0),
            peg_qadr: 0,
            peg_geom: GeomId::from_index(0),
            box_body: BodyId::from_index(0),
            box_geoms: [GeomId::from_index(0); 4],
        }
    }
}

impl PegInsertionSide {
    /// The task, with the build shapes until the first reset draws the episode's.
    pub fn new() -> Self {
        Self::default()
    }

    /// The peg's pose.
    fn peg_frame(&self, ctx: &TaskCtx) -> Frame {
        (ctx.body_pos(self.peg), rotation(ctx.body_quat(self.peg)))
    }

    /// `peg_head_pose`: the head's centre, one half length along the peg's axis.
    pub fn peg_head(&self, ctx: &TaskCtx) -> Frame {
        offset(&self.peg_frame(ctx), [self.geometry.half_length, 0.0, 0.0])
    }

    /// `box_hole_pose`: the box's pose moved to the hole's centre.
    pub fn box_hole(&self, ctx: &TaskCtx) -> Frame {
        let box_frame = (
            ctx.body_pos(self.box_body),
            rotation(ctx.body_quat(self.box_body)),
        );
        let [cy, cz] = self.geometry.center;
        offset(&box_frame, [0.0, cy, cz])
    }

    /// `goal_pose`: where the peg's centre is when its head is at the hole's centre.
    pub fn goal(&self, ctx: &TaskCtx) -> Frame {
        offset(&self.box_hole(ctx), [-self.geometry.half_length, 0.0, 0.0])
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PegInsertionSideEval {
        let head = local(&self.box_hole(ctx), &self.peg_head(ctx).0);
        let r = self.geometry.hole_radius();
        let inside = |x: f64| -r <= x && x <= r;
        PegInsertionSideEval {
            success: -INSERTED_DEPTH <= head.x && inside(head.y) && inside(head.z),
            peg_head_pos_at_hole: head.into(),
        }
    }
}

impl Task for PegInsertionSide {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene (build order: peg, box with the hole), its shapes drawn per episode --------
    fn build(&self, scene: &mut Scene) {
        let g = &self.geometry;
        let colours = [PEG_TAIL_RGBA, PEG_HEAD_RGBA];
        scene.add_twocolor_peg("peg", g.half_length, g.radius, colours, PEG_BUILD_POS);
        scene.add_finger_pairs("peg", FINGER_PATCH_RADIUS);
        scene.add_box_with_hole("box_with_hole", &g.box_walls(), BOX_RGBA, BOX_BUILD_POS);
        add_cameras(scene, self.cameras());
    }

    fn robot_repose(&self) -> Option<&'static [f64]> {
        Some(&ROBOT_QPOS)
    }

    fn repose_noise(&self) -> Option<f64> {
        Some(ROBOT_QPOS_NOISE)
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.peg = body_id(model, "peg")?;
        self.peg_qadr = free_joint_qpos(model, "peg")?;
        self.peg_geom = model.require_geom("peg")?;
        self.box_body = body_id(model, "box_with_hole")?;
        for (k, g) in self.box_geoms.iter_mut().enumerate() {
            *g = model.require_geom(&format!("box_with_hole_{k}"))?;
        }
        Ok(())
    }

    fn reconfigures(&self) -> bool {
        true
    }

    fn draw_geometry(&mut self, numpy: &mut NumpyRandomState) {
        self.geometry = PegGeometry::draw(numpy);
    }

    fn geometry(&self) -> Vec<f64> {
        self.geometry.to_vec()
    }

    fn check_geometry(&self, values: &[f64]) -> Result<(), String> {
        PegGeometry::from_slice(values).map(|_| ())
    }

    fn set_geometry(&mut self, values: &[f64]) {
        if let Ok(g) = PegGeometry::from_slice(values) {
            self.geometry = g;
        }
    }

    fn apply_geometry(&self, model: &mut Model) -> Result<(), MjError> {
        let g = &self.geometry;
        let half = [g.half_length, g.radius, g.radius];
        model.set_box_geom(self.peg_geom, half, [0.0; 3])?;
        let (mass, inertia) = peg_inertia(g.half_length, g.radius);
        model.set_body_inertia(self.peg, mass, inertia)?;
        for (geom, (centre, half)) in self.box_geoms.iter().zip(g.box_walls()) {
            model.set_box_geom(*geom, half, centre)?;
        }
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.peg
    }

    // ---- episode initialisation (torch draws: rand(2), rand(3), rand(2), rand(3)), in
    // float32 as upstream; the robot's second pose draw is the env's (robot_repose) ---------
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let g = self.geometry;
        let [x, y] = random_xy(torch, PEG_SPAWN);
        let quat = random_yaw(torch, PEG_YAW_HALF_RANGE);
        set_free_pose(data, self.peg_qadr, [x, y, g.radius as f32 as f64], quat);
        let [x, y] = random_xy(torch, BOX_SPAWN);
        let quat = random_yaw(torch, BOX_YAW_HALF_RANGE);
        let model = data.model().clone();
        let pos = [x, y, g.half_length as f32 as f64];
        set_mocap_pose(&model, data, self.box_body, pos, quat);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        &INFO_KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        let e = self.eval(ctx);
        info[0] = e.success as u8 as f64;
        info[1..4].copy_from_slice(&e.peg_head_pos_at_hole);
    }

    fn bool_info(&self, key: &str) -> bool {
        key == INFO_KEYS[0]
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        if state {
            let g = &self.geometry;
            out.pose("peg_pose", ctx.body_pos(self.peg), ctx.body_quat(self.peg));
            out.put("peg_half_size", [g.half_length, g.radius, g.radius]);
            // The hole's frame turns with the box: its raw quaternion is the box's.
            let hole = self.box_hole(ctx).0;
            out.pose("box_hole_pose", hole, ctx.body_quat(self.box_body));
            out.scalar("box_hole_radius", g.hole_radius());
        }
    }

    // ---- dense reward (max 10) -----------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        if info[0] > 0.0 {
            return MAX_REWARD;
        }
        // Reaching a point behind the peg's centre, then grasping it.
        let target = offset(&self.peg_frame(ctx), [GRASP_TARGET_OFFSET, 0.0, 0.0]).0;
        let reach = 1.0 - (REACH_SCALE * (ctx.tcp_link_pos() - target).norm()).tanh();
        let grasped = ctx.is_grasping_within(GRASP_MAX_ANGLE);
        let mut reward = reach + grasped as u8 as f64;
        // Lining the peg's head and centre up with the hole's axis.
        let goal = self.goal(ctx);
        let head = self.peg_head(ctx).0;
        let yz = |p: Vector3<f64>| p.yz().norm();
        let head_off = yz(local(&goal, &head));
        let centre_off = yz(local(&goal, &ctx.body_pos(self.peg)));
        let lined = LINE_UP_MEAN * (head_off + centre_off) + LINE_UP_MAX * head_off.max(centre_off);
        reward += PRE_INSERTION_WEIGHT * (1.0 - lined.tanh()) * grasped as u8 as f64;
        // Pushing the head to the hole's centre once lined up.
        let pre_inserted = head_off < PRE_INSERTED_DIST && centre_off < PRE_INSERTED_DIST;
        let depth = local(&self.box_hole(ctx), &head).norm();
        if grasped && pre_inserted {
            reward += INSERTION_WEIGHT * closeness(depth);
        }
        reward
    }

    fn grasp_flag(&self) -> &'static str {
        ABSENT_GRASP_FLAG
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["peg", "box_with_hole"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        tabletop_cameras(
            ([0.0, -0.3, 0.2], [0.0, 0.0, 0.1]),
            ([0.5, -0.5, 0.8], [0.05, -0.1, 0.4]),
        )
    }
}
