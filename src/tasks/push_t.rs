//! PushT-v1 (docs/tasks.md §10): push a T-shaped block on a white table until it covers 90 %
//! of a fixed goal T, with the panda_stick (ManiSkill's Diffusion-Policy push-T).
//!
//! The T is two boxes, a 0.2 × 0.05 bar and a 0.05 × 0.15 stem, 0.04 thick, whose frame sits
//! where ManiSkill puts it: 0.0375 m along the stem from the bar's centre (upstream's centre of
//! mass figure; the boxes' true centre of mass is 5.4 mm further along the stem, and SAPIEN
//! and mjskill both simulate about that one); it weighs 0.7 kg, not upstream's nominal 0.8
//! ([`TEE_MASS`]). The goal T is a flat visual-only copy at a fixed
//! pose; a small grey disc marks the stick's start.
//!
//! Success is ManiSkill's "pseudo render" ([`PseudoRender`]): the T's pixels on a 64 × 64
//! grid 0.3 m wide are carried into the goal T's frame and counted where they land on the goal
//! T's pixels; at least 90 % of the goal's 825 pixels covered is success. The dense reward is
//! pose based instead (rotation and distance to the goal, plus a little for the stick near the
//! T), 3 on success.
use std::f64::consts::PI;

use nalgebra::Vector3;

use super::push_cube::ABSENT_GRASP_FLAG;
use super::{
    add_cameras, body_id, free_joint_qpos, set_free_pose, set_mocap_pose, tabletop_cameras,
    CameraDef, ObsWriter, Task, TaskCtx, TARGET_QUAT, TARGET_RED,
};
use crate::mjcf::props::Rgba;
use crate::mjcf::Scene;
use crate::mujoco::{BodyId, Data, MjError, Model};
use crate::rng::TorchGenerator;

// ---- constants (docs/tasks.md §10) --------------------------------------------------------------
/// Maximum dense reward (the value given on success).
pub const MAX_REWARD: f64 = 3.0;
/// The joint positions the task's `WhiteTableSceneBuilder` poses the panda_stick at after the
/// common table scene, with fresh noise (its stick's tip 2 cm above the table, near
/// [`EE_START`]).
pub const ROBOT_QPOS: [f64; 7] = [0.662, 0.212, 0.086, -2.685, -0.115, 2.898, 1.673];
/// Half extents of the T's bar (m).
pub const BAR_HALF: [f64; 3] = [0.1, 0.025, TEE_HALF_THICKNESS];
/// Half extents of the T's stem (m): as the bar, three quarters as long, turned 90°.
pub const STEM_HALF: [f64; 3] = [0.025, 0.075, TEE_HALF_THICKNESS];
/// Half thickness of the T (m).
pub const TEE_HALF_THICKNESS: f64 = 0.02;
/// Half thickness of the flat goal T (m).
const GOAL_HALF_THICKNESS: f64 = 1e-4;
/// Upstream's "centre of mass" of the T along its stem, measured from the bar's centre (m):
/// the T's frame origin.
pub const COM_Y: f64 = 0.0375;
/// The bar's and the stem's centres in the T's frame (m).
pub const BAR_CENTRE: [f64; 3] = [0.0, -COM_Y, 0.0];
/// The stem's centre: flush against the bar, four bar half widths from its centre.
pub const STEM_CENTRE: [f64; 3] = [0.0, 4.0 * 0.025 - COM_Y, 0.0];
/// Mass of the T (kg): the boxes' 7·10⁻⁴ m³ at SAPIEN's default density, 1000 kg/m³.
/// (Upstream sets `builder._mass = 0.8`, which SAPIEN's actor builder does not read: ManiSkill's
/// T weighs 0.7 kg.)
pub const TEE_MASS: f64 = 0.7;
/// Friction of the T's material (static = dynamic).
pub const TEE_FRICTION: f64 = 3.0;
/// The T's colour (upstream's `TARGET_RED`) and the goal T's grey (128/255).
pub const TEE_RGBA: Rgba = TARGET_RED;
/// Grey of the goal T and of the stick's start marker.
pub const GOAL_RGBA: Rgba = [128.0 / 255.0, 128.0 / 255.0, 128.0 / 255.0, 1.0];
/// Build position of the three actors (before the first reset), as upstream.
const BUILD_POS: [f64; 3] = [0.0, 0.0, 0.1];
/// The goal T's xy (m) and yaw (rad); it rests [`GOAL_Z`] above the table.
pub const GOAL_OFFSET: [f32; 2] = [-0.156, -0.1];
/// The goal T's yaw: 5π/3.
pub const GOAL_Z_ROT: f64 = 5.0 / 3.0 * PI;
/// Height of the goal T's frame and of the start marker (m).
pub const GOAL_Z: f64 = 1e-3;
/// The spawn box of the T's xy relative to the goal: x in [−0.1, 0.1), y in [−0.1, 0.2) (m).
pub const SPAWN_LENGTH: [f32; 2] = [0.2, 0.3];
/// The spawn box's low corner relative to the goal (m).
pub const SPAWN_OFFSET: [f32; 2] = [-0.1, -0.1];
/// Height of the T's frame at spawn: its half thickness plus a millimetre (m).
pub const SPAWN_Z: f64 = 0.04 / 2.0 + 1e-3;
/// The stick's start marker (`goal_ee`): a disc of this radius (m) and half thickness at
/// `ee_starting_pos2D`.
const EE_MARKER_RADIUS: f64 = 0.02;
const EE_MARKER_HALF_THICKNESS: f64 = 1e-4;
/// Upstream's `ee_starting_pos2D` (m).
pub const EE_START: [f64; 3] = [-0.321, 0.284, 1e-3];
/// Success: at least this fraction of the goal T's pixels covered.
pub const INTERSECTION_THRESH: f64 = 0.90;
/// The pseudo render's grid: `RES` × `RES` pixels over ±`UV_HALF_WIDTH` (m).
pub const RES: usize = 64;
/// Half width of the pseudo render's grid (m).
pub const UV_HALF_WIDTH: f64 = 0.15;
/// Weights of the reward's terms: rotation and distance ½ each, the stick's reach 1/20.
const ROT_WEIGHT: f64 = 0.5;
const DIST_WEIGHT: f64 = 0.5;
const REACH_WEIGHT: f64 = 1.0 / 20.0;
/// The shaping scale of the distance and reach terms (`1 − tanh(5 d)`).
const REWARD_SCALE: f64 = 5.0;

evaluation! {
    /// PushT's `evaluate()`.
    pub struct PushTEval {
        /// The T covers at least 90 % of the goal T's pixels.
        success: bool,
    }
}

/// `quat_to_z_euler`: the yaw in [0, 2π] of a quaternion (w, x, y, z) that turns about z only,
/// `2·acos(±w)` with the sign of z (upstream's fix of the double cover). `w` is clamped to
/// [−1, 1] (where upstream's float32 `acos` would give NaN).
pub fn z_euler(q: [f64; 4]) -> f64 {
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    2.0 * (q[0] * sign).clamp(-1.0, 1.0).acos()
}

/// [`z_euler`] in float32, as the pseudo render computes it.
fn z_euler_f32(q: [f32; 4]) -> f32 {
    let sign = if q[3] < 0.0 { -1.0f32 } else { 1.0 };
    2.0 * (q[0] * sign).clamp(-1.0, 1.0).acos()
}

/// A 2-D rigid transform as upstream's 3 × 3 float32 matrices.
type Mat3 = [[f32; 3]; 3];

/// `quat_to_zrot` with the translation `(x, y)`: the homogeneous 2-D transform of a pose.
fn zrot(q: [f32; 4], x: f32, y: f32) -> Mat3 {
    let a = z_euler_f32(q);
    let (s, c) = (a.sin(), a.cos());
    [[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]]
}

/// `a @ b` in float32, each entry summed in index order.
fn matmul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| {
        std::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j])
    })
}

/// ManiSkill's pseudo render of the T in the goal T's frame (`pseudo_render_intersection`),
/// in float32 as upstream: the egocentric T rasterised once on the grid, its pixel centres
/// carried by the T's pose into the goal's frame and truncated to pixel indices (indices off
/// the grid go to pixel (0, 0), as upstream), and the pixels that land on the goal's counted.
#[derive(Debug, Clone)]
pub struct PseudoRender {
    /// The T's pixels in image order: row `r` has bit `c` set where the T is.
    mask: [u64; RES],
    /// Grid coordinates (m) of the T's pixels, in the T's frame.
    pixels: Vec<[f32; 2]>,
    /// Number of the T's pixels (the goal's area).
    area: u32,
    /// World to goal frame (upstream's `world_to_goal_trans`).
    world_to_goal: Mat3,
}

impl PseudoRender {
    /// Pixels per metre of the grid, `(RES/2)/UV_HALF_WIDTH`, in float32.
    fn scale() -> f32 {
        ((RES / 2) as f64 / UV_HALF_WIDTH) as f32
    }

    /// The render of the T: the two boxes' corners to pixel indices (truncated), each box
    /// filling its half-open index range, then the image flipped upside down.
    pub fn new() -> PseudoRender {
        let (k, half) = (Self::scale(), (RES / 2) as f32);
        let index = |v: f32| (v * k + half) as i64;
        let mut mask = [0u64; RES];
        // (x low, x high, y low, y high) of each box around the bar's centre, then shifted
        // to the T's frame.
        for (xl, xh, yl, yh) in [
            (-0.1f32, 0.1f32, -0.025f32, 0.025f32),
            (-0.025, 0.025, 0.025, 0.175),
        ] {
            let com = COM_Y as f32;
            let (x0, x1) = (index(xl), index(xh));
            let (y0, y1) = (index(yl - com), index(yh - com));
            for y in y0..y1 {
                for x in x0..x1 {
                    // upstream writes `render.T[x, y]`, then flips the rows.
                    mask[RES - 1 - y as usize] |= 1 << x;
                }
            }
        }
        let mut pixels = Vec::new();
        for (r, row) in mask.iter().enumerate() {
            for c in 0..RES {
                if (row >> c) & 1 == 1 {
                    let u = ((c as f32 - half) + 0.5) / k;
                    let v = (-(r as f32 - half) + 0.5) / k;
                    pixels.push([u, v]);
                }
            }
        }
        let area = mask.iter().map(|r| r.count_ones()).sum();
        // The goal's transform from its yaw alone (upstream's `goal_fake_quat` has z = 0)
        // and its xy, inverted in double precision and rounded.
        let half_yaw = ((GOAL_Z_ROT as f32) / 2.0).cos();
        let g = zrot([half_yaw, 0.0, 0.0, 0.0], GOAL_OFFSET[0], GOAL_OFFSET[1]);
        PseudoRender {
            mask,
            pixels,
            area,
            world_to_goal: invert_rigid(&g),
        }
    }

    /// The number of the T's (and the goal's) pixels.
    #[cfg_attr(not(test), allow(dead_code))] // read by the tests
    pub fn area(&self) -> u32 {
        self.area
    }

    /// The fraction of the goal T's pixels the T covers at position `(x, y)` with quaternion
    /// `q` (w, x, y, z), as upstream computes it from the float32 pose. No allocation.
    pub fn intersection(&self, x: f32, y: f32, q: [f32; 4]) -> f64 {
        let m = matmul(&self.world_to_goal, &zrot(q, x, y));
        let (k, half) = (Self::scale(), (RES / 2) as f32);
        // `rendered[ix]` has bit `iy` set where a pixel of the T lands.
        let mut rendered = [0u64; RES];
        for &[u, v] in &self.pixels {
            let w = m[2][0] * u + m[2][1] * v + m[2][2];
            let gx = (m[0][0] * u + m[0][1] * v + m[0][2]) / w;
            let gy = (m[1][0] * u + m[1][1] * v + m[1][2]) / w;
            let (ix, iy) = ((gx * k + half) as i64, (gy * k + half) as i64);
            let valid = (0..RES as i64).contains(&ix) && (0..RES as i64).contains(&iy);
            let (ix, iy) = if valid {
                (ix as usize, iy as usize)
            } else {
                (0, 0)
            };
            rendered[ix] |= 1 << iy;
        }
        // Upstream transposes the render and flips its rows before comparing: pixel
        // (ix, iy) lands on the goal's row RES−1−iy, column ix.
        let mut hits = 0u32;
        for (ix, col) in rendered.iter().enumerate() {
            for iy in 0..RES {
                if (col >> iy) & 1 == 1 && (self.mask[RES - 1 - iy] >> ix) & 1 == 1 {
                    hits += 1;
                }
            }
        }
        hits as f64 / self.area as f64
    }

    /// The goal's world-to-goal transform (float32, as upstream's).
    #[cfg_attr(not(test), allow(dead_code))] // read by the tests
    pub fn world_to_goal(&self) -> [[f32; 3]; 3] {
        self.world_to_goal
    }
}

impl Default for PseudoRender {
    fn default() -> Self {
        Self::new()
    }
}

/// The inverse of a float32 2-D transform `[[c, −s, x], [s, c, y], [0, 0, 1]]` (in double
/// precision, rounded to float32).
fn invert_rigid(g: &Mat3) -> Mat3 {
    let (c, s) = (g[0][0] as f64, g[1][0] as f64);
    let (x, y) = (g[0][2] as f64, g[1][2] as f64);
    let det = c * c + s * s;
    let (ci, si) = (c / det, s / det);
    [
        [ci as f32, si as f32, (-(ci * x + si * y)) as f32],
        [(-si) as f32, ci as f32, (si * x - ci * y) as f32],
        [0.0, 0.0, 1.0],
    ]
}

/// The T's quaternion (w, x, y, z) for yaw `u·2π` of a uniform draw `u`, in float32 as
/// upstream: `(cos(a/2), 0, 0, sin(a/2))`, not sign-standardised.
pub fn spawn_quat(u: f32) -> [f64; 4] {
    let a = u * (2.0 * std::f32::consts::PI);
    let half = a / 2.0;
    [half.cos() as f64, 0.0, 0.0, half.sin() as f64]
}

/// PushT-v1.
#[derive(Debug, Clone, Default)]
pub struct PushT {
    tee: BodyId,
    tee_qadr: usize,
    goal: BodyId,
    ee_goal: BodyId,
    render: PseudoRender,
}

impl PushT {
    /// The task (panda_stick only, as upstream).
    pub fn new() -> Self {
        Self::default()
    }

    /// The goal T's position, as upstream stores it (float32).
    pub fn goal_pos() -> [f64; 3] {
        [
            GOAL_OFFSET[0] as f64,
            GOAL_OFFSET[1] as f64,
            GOAL_Z as f32 as f64,
        ]
    }

    /// The goal T's quaternion `euler2quat(0, 0, 5π/3)` (w, x, y, z), in float32 as upstream:
    /// w is negative.
    pub fn goal_quat() -> [f64; 4] {
        let half = GOAL_Z_ROT / 2.0;
        [half.cos() as f32 as f64, 0.0, 0.0, half.sin() as f32 as f64]
    }

    /// The fraction of the goal T the T covers now.
    pub fn intersection(&self, ctx: &TaskCtx) -> f64 {
        let p = ctx.body_pos(self.tee);
        let q = ctx.body_quat(self.tee).map(|x| x as f32);
        self.render.intersection(p.x as f32, p.y as f32, q)
    }

    /// `evaluate()`, typed.
    pub fn eval(&self, ctx: &TaskCtx) -> PushTEval {
        PushTEval {
            success: self.intersection(ctx) >= INTERSECTION_THRESH,
        }
    }
}

impl Task for PushT {
    fn max_reward(&self) -> f64 {
        MAX_REWARD
    }

    // ---- scene (build order: Tee, goal_Tee, goal_ee; the table drawn white) --------------
    fn build(&self, scene: &mut Scene) {
        scene.whiten_table();
        let boxes = [(BAR_CENTRE, BAR_HALF), (STEM_CENTRE, STEM_HALF)];
        // PhysX averages the two materials' friction; MuJoCo takes the larger, so the T
        // carries the average with the default material (table, stick).
        let friction = (TEE_FRICTION + crate::mjcf::DEFAULT_FRICTION) / 2.0;
        let tee_mass = Some((TEE_MASS, friction));
        scene.add_box_union("Tee", &boxes, TEE_RGBA, tee_mass, BUILD_POS);
        let flat = |(c, h): ([f64; 3], [f64; 3])| (c, [h[0], h[1], GOAL_HALF_THICKNESS]);
        scene.add_box_union("goal_Tee", &boxes.map(flat), GOAL_RGBA, None, BUILD_POS);
        let (r, t) = (EE_MARKER_RADIUS, EE_MARKER_HALF_THICKNESS);
        scene.add_marker_disc("goal_ee", r, t, GOAL_RGBA);
        add_cameras(scene, self.cameras());
    }

    fn robot_repose(&self) -> Option<&'static [f64]> {
        Some(&ROBOT_QPOS)
    }

    fn resolve(&mut self, model: &Model) -> Result<(), MjError> {
        self.tee = body_id(model, "Tee")?;
        self.tee_qadr = free_joint_qpos(model, "Tee")?;
        self.goal = body_id(model, "goal_Tee")?;
        self.ee_goal = body_id(model, "goal_ee")?;
        Ok(())
    }

    fn grasp_object(&self) -> BodyId {
        self.tee
    }

    // ---- episode initialisation (torch draws: rand(1) x, rand(1) y, rand(1) yaw), float32 --
    fn initialize_episode(&mut self, data: &mut Data, torch: &mut TorchGenerator) {
        let model = data.model().clone();
        set_mocap_pose(&model, data, self.goal, Self::goal_pos(), Self::goal_quat());
        let mut u = [0f32; 1];
        let mut xy = [0f64; 2];
        for k in 0..2 {
            torch.fill_rand(&mut u);
            let offset = u[0] * SPAWN_LENGTH[k] + SPAWN_OFFSET[k];
            xy[k] = (GOAL_OFFSET[k] + offset) as f64;
        }
        torch.fill_rand(&mut u);
        let pos = [xy[0], xy[1], SPAWN_Z as f32 as f64];
        set_free_pose(data, self.tee_qadr, pos, spawn_quat(u[0]));
        let ee = EE_START.map(|x| x as f32 as f64);
        set_mocap_pose(&model, data, self.ee_goal, ee, TARGET_QUAT);
    }

    // ---- evaluate ------------------------------------------------------------------------
    fn info_keys(&self) -> &'static [&'static str] {
        PushTEval::KEYS
    }

    fn evaluate(&self, ctx: &TaskCtx, info: &mut [f64]) {
        self.eval(ctx).write(info);
    }

    // ---- observation extras ------------------------------------------------------------------
    fn observe_extra(&self, ctx: &TaskCtx, _info: &[f64], state: bool, out: &mut ObsWriter) {
        let (tcp, tcp_q) = ctx.tcp_link_pose();
        out.pose("tcp_pose", tcp, tcp_q);
        if state {
            out.vec3("goal_pos", ctx.body_pos(self.goal));
            out.pose("obj_pose", ctx.body_pos(self.tee), ctx.body_quat(self.tee));
        }
    }

    // ---- dense reward (max 3) ------------------------------------------------------------------
    fn dense_reward(&self, ctx: &TaskCtx, info: &[f64]) -> f64 {
        if PushTEval::read(info).success {
            return MAX_REWARD;
        }
        let tee: Vector3<f64> = ctx.body_pos(self.tee);
        let goal = ctx.body_pos(self.goal);
        // Rotation: the cosine of the yaw error, mapped to [0, 1] and squared.
        let rot = (z_euler(ctx.body_quat(self.tee)) - GOAL_Z_ROT).cos();
        let rotation = ((rot + 1.0) / 2.0).powi(2);
        // Distance: the T's xy towards the goal's.
        let d = (tee.xy() - goal.xy()).norm();
        let distance = (1.0 - (REWARD_SCALE * d).tanh()).powi(2);
        // Reach: the stick's tip near the T's frame origin (3-D).
        let r = (tee - ctx.tcp_link_pos()).norm();
        let reach = (1.0 - (REWARD_SCALE * r).tanh()).sqrt();
        ROT_WEIGHT * rotation + DIST_WEIGHT * distance + REACH_WEIGHT * reach
    }

    fn grasp_flag(&self) -> &'static str {
        ABSENT_GRASP_FLAG
    }

    fn actor_names(&self) -> &'static [&'static str] {
        &["Tee", "goal_Tee", "goal_ee"]
    }

    fn cameras(&self) -> (CameraDef, CameraDef) {
        let look = ([0.3, 0.0, 0.6], [-0.1, 0.0, 0.1]);
        tabletop_cameras(look, look)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rendered_t_has_upstreams_825_pixels_and_shape() {
        let r = PseudoRender::new();
        // Bar: columns 10..53 × 11 rows; stem: columns 26..37 × 32 rows.
        assert_eq!(r.area(), 43 * 11 + 11 * 32);
        // The bar's rows are image rows 63−28 ..= 63−18 (flipped), the stem's above them.
        assert_eq!(r.mask[63 - 18], ((1u64 << 53) - 1) & !((1u64 << 10) - 1));
        assert_eq!(r.mask[63 - 40], ((1u64 << 37) - 1) & !((1u64 << 26) - 1));
        assert_eq!(r.mask[63 - 17], 0);
        assert_eq!(r.mask[63 - 61], 0);
    }

    #[test]
    fn the_t_on_the_goal_covers_it_and_far_away_covers_nothing() {
        let r = PseudoRender::new();
        let q = PushT::goal_quat().map(|x| x as f32);
        let [x, y] = GOAL_OFFSET;
        // Exactly on the goal, upstream's render covers 782 of the 825 pixels: the grid's
        // pixel centres sit half a pixel off in y, and one 43-pixel row of the bar misses.
        let full = r.intersection(x, y, q);
        assert_eq!(full, 782.0 / 825.0);
        // Turned half a turn about its frame: the stem points the other way.
        let turned = [q[3], 0.0, 0.0, -q[0]];
        let half = r.intersection(x, y, turned);
        assert!(half < INTERSECTION_THRESH && half > 0.0, "{half}");
        assert_eq!(r.intersection(x + 0.5, y, q), 0.0);
    }

    #[test]
    fn z_euler_is_the_yaw_whatever_the_quaternions_sign() {
        for yaw in [0.1, 1.0, 3.0, 4.5, 6.0] {
            let q = [(yaw / 2.0f64).cos(), 0.0, 0.0, (yaw / 2.0f64).sin()];
            let neg = q.map(|x| -x);
            assert!((z_euler(q) - yaw).abs() < 1e-9, "{yaw}");
            assert!((z_euler(neg) - yaw).abs() < 1e-9, "{yaw}");
        }
    }

    #[test]
    fn the_box_union_inertia_puts_the_centre_of_mass_along_the_stem() {
        let boxes = [(BAR_CENTRE, BAR_HALF), (STEM_CENTRE, STEM_HALF)];
        let (com, _) = crate::mjcf::props::box_union_inertia(&boxes, TEE_MASS);
        // (4·(−0.0375) + 3·0.0625)/7 = 0.0375/7.
        assert!((com[1] - 0.0375 / 7.0).abs() < 1e-15, "{com:?}");
        assert_eq!([com[0], com[2]], [0.0, 0.0]);
    }
}
