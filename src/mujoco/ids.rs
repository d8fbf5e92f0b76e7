//! Typed ids and poses: which kind of object an index names ([`BodyId`], [`JointId`],
//! [`GeomId`], [`ActuatorId`], [`MocapId`], [`CameraId`]), looked up by name on the
//! [`Model`], and the accessors that read one object's slot of MuJoCo's flat arrays
//! (`xpos[3·b..3·b+3]` and the like) so that no layer above does index arithmetic. [`Pose`]
//! is the one codec of the 7-number pose `[x, y, z, qw, qx, qy, qz]` that states, state
//! dicts, actors and controller targets store. Every accessor returns fixed-size arrays:
//! nothing allocates.
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::{Data, MjError, Model, ObjType, Result};

macro_rules! typed_ids {
    ($($(#[$doc:meta])* $name:ident;)*) => {
        $(
            $(#[$doc])*
            ///
            /// The default is index 0 (for the world body: a placeholder until resolved).
            #[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
            pub struct $name(usize);

            impl $name {
                /// The id of the object at `index` of its kind (for ids that come from
                /// MuJoCo's own arrays; names are looked up on the [`Model`]).
                pub const fn from_index(index: usize) -> Self {
                    $name(index)
                }

                /// The object's index in MuJoCo's arrays of its kind.
                pub const fn index(self) -> usize {
                    self.0
                }
            }
        )*
    };
}

typed_ids! {
    /// A body (`mjOBJ_BODY`).
    BodyId;
    /// A joint (`mjOBJ_JOINT`).
    JointId;
    /// A geom (`mjOBJ_GEOM`).
    GeomId;
    /// An actuator (`mjOBJ_ACTUATOR`).
    ActuatorId;
    /// A mocap body's slot in `mocap_pos` / `mocap_quat` (`body_mocapid`).
    MocapId;
    /// A camera (`mjOBJ_CAMERA`).
    CameraId;
}

/// A pose as MuJoCo and ManiSkill store it: position and quaternion `(w, x, y, z)`, seven
/// numbers in that order. The quaternion is kept as given (not renormalised), so that a
/// pose read, stored and restored is bitwise the same.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position.
    pub pos: [f64; 3],
    /// Orientation `(w, x, y, z)`.
    pub quat: [f64; 4],
}

impl Pose {
    /// Numbers of the stored form.
    pub const LEN: usize = 7;

    /// The pose of the stored form `[x, y, z, qw, qx, qy, qz]`.
    pub const fn from_array(v: [f64; 7]) -> Pose {
        Pose {
            pos: [v[0], v[1], v[2]],
            quat: [v[3], v[4], v[5], v[6]],
        }
    }

    /// The pose stored in the first [`Pose::LEN`] numbers of `v`; `None` when `v` is shorter.
    pub fn from_slice(v: &[f64]) -> Option<Pose> {
        let v: &[f64; 7] = v.get(..Self::LEN)?.try_into().ok()?;
        Some(Pose::from_array(*v))
    }

    /// The stored form `[x, y, z, qw, qx, qy, qz]`.
    pub const fn to_array(&self) -> [f64; 7] {
        let (p, q) = (self.pos, self.quat);
        [p[0], p[1], p[2], q[0], q[1], q[2], q[3]]
    }

    /// The pose of an isometry (its quaternion's `w, i, j, k`).
    pub fn from_isometry(iso: &Isometry3<f64>) -> Pose {
        let t = iso.translation.vector;
        let q = iso.rotation;
        Pose {
            pos: [t.x, t.y, t.z],
            quat: [q.w, q.i, q.j, q.k],
        }
    }

    /// Position as a vector.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::from(self.pos)
    }

    /// The orientation as the quaternion stored (taken as unit, not renormalised).
    pub fn rotation(&self) -> UnitQuaternion<f64> {
        let [w, x, y, z] = self.quat;
        UnitQuaternion::new_unchecked(Quaternion::new(w, x, y, z))
    }

    /// The pose as an isometry ([`Pose::rotation`]'s quaternion).
    pub fn isometry(&self) -> Isometry3<f64> {
        let [x, y, z] = self.pos;
        Isometry3::from_parts(Translation3::new(x, y, z), self.rotation())
    }

    /// The orientation renormalised to unit length, for poses from outside mjskill's own
    /// state (ManiSkill's float32 state dicts, reference files) and where a rotation must be
    /// exactly unit (the solvers' targets).
    pub fn rotation_renormalized(&self) -> UnitQuaternion<f64> {
        let [w, x, y, z] = self.quat;
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
    }

    /// The pose as an isometry with [`Pose::rotation_renormalized`]'s quaternion.
    pub fn isometry_renormalized(&self) -> Isometry3<f64> {
        let [x, y, z] = self.pos;
        Isometry3::from_parts(Translation3::new(x, y, z), self.rotation_renormalized())
    }
}

/// `N` numbers starting at `N·i` of a flat per-object array.
fn slot<T: Copy + Default, const N: usize>(flat: &[T], i: usize) -> [T; N] {
    let mut out = [T::default(); N];
    out.copy_from_slice(&flat[N * i..N * i + N]);
    out
}

impl Model {
    /// The id of a named object of kind `ty`, or an error naming it.
    fn require<T>(&self, ty: ObjType, name: &str, id: fn(usize) -> T) -> Result<T> {
        self.require_id(ty, name).map(id)
    }

    /// The body named `name`, or an error naming it.
    pub fn require_body(&self, name: &str) -> Result<BodyId> {
        self.require(ObjType::Body, name, BodyId)
    }

    /// The joint named `name`, or an error naming it.
    pub fn require_joint(&self, name: &str) -> Result<JointId> {
        self.require(ObjType::Joint, name, JointId)
    }

    /// The geom named `name`, or an error naming it.
    pub fn require_geom(&self, name: &str) -> Result<GeomId> {
        self.require(ObjType::Geom, name, GeomId)
    }

    /// The actuator named `name`, or an error naming it.
    pub fn require_actuator(&self, name: &str) -> Result<ActuatorId> {
        self.require(ObjType::Actuator, name, ActuatorId)
    }

    /// The camera named `name`, or an error naming it.
    pub fn require_camera(&self, name: &str) -> Result<CameraId> {
        self.require(ObjType::Camera, name, CameraId)
    }

    /// The mocap slot of body `b`; `None` unless it is a mocap body.
    pub fn body_mocap(&self, b: BodyId) -> Option<MocapId> {
        let m = self.body_mocapid()[b.0];
        (m >= 0).then_some(MocapId(m as usize))
    }

    /// The mocap slot of body `b`, or an error naming the body.
    pub fn require_mocap(&self, b: BodyId) -> Result<MocapId> {
        self.body_mocap(b).ok_or_else(|| {
            let name = self.name(ObjType::Body, b.0);
            MjError::Invalid(format!("body {name:?} is not a mocap body"))
        })
    }

    /// The `qpos` address of joint `j`.
    pub fn joint_qpos_adr(&self, j: JointId) -> usize {
        self.jnt_qposadr()[j.0] as usize
    }

    /// The `qvel` (dof) address of joint `j`.
    pub fn joint_dof_adr(&self, j: JointId) -> usize {
        self.jnt_dofadr()[j.0] as usize
    }

    /// Body `b`'s centre of mass in its own frame (`body_ipos`).
    pub fn body_com_offset(&self, b: BodyId) -> [f64; 3] {
        slot(self.body_ipos(), b.0)
    }

    /// Geom `g`'s colour (`geom_rgba`).
    pub fn geom_color(&self, g: GeomId) -> [f32; 4] {
        slot(self.geom_rgba(), g.0)
    }

    /// Geom `g`'s size parameters (`geom_size`).
    pub fn geom_dims(&self, g: GeomId) -> [f64; 3] {
        slot(self.geom_size(), g.0)
    }

    /// Geom `g`'s pose in its body's frame (`geom_pos`, `geom_quat`).
    pub fn geom_local_pose(&self, g: GeomId) -> Pose {
        Pose {
            pos: slot(self.geom_pos(), g.0),
            quat: slot(self.geom_quat(), g.0),
        }
    }
}

impl Data {
    /// Body `b`'s world position (`xpos`).
    pub fn body_pos(&self, b: BodyId) -> [f64; 3] {
        slot(self.xpos(), b.0)
    }

    /// Body `b`'s world orientation `(w, x, y, z)` (`xquat`).
    pub fn body_quat(&self, b: BodyId) -> [f64; 4] {
        slot(self.xquat(), b.0)
    }

    /// Body `b`'s world pose (`xpos`, `xquat`).
    pub fn body_pose(&self, b: BodyId) -> Pose {
        Pose {
            pos: self.body_pos(b),
            quat: self.body_quat(b),
        }
    }

    /// Body `b`'s world rotation matrix, row-major (`xmat`).
    pub fn body_mat(&self, b: BodyId) -> [f64; 9] {
        slot(self.xmat(), b.0)
    }

    /// Camera `c`'s world position (`cam_xpos`).
    pub fn camera_pos(&self, c: CameraId) -> [f64; 3] {
        slot(self.cam_xpos(), c.0)
    }

    /// Camera `c`'s world rotation matrix, row-major (`cam_xmat`).
    pub fn camera_mat(&self, c: CameraId) -> [f64; 9] {
        slot(self.cam_xmat(), c.0)
    }

    /// Mocap slot `m`'s pose (`mocap_pos`, `mocap_quat`).
    pub fn mocap_pose(&self, m: MocapId) -> Pose {
        Pose {
            pos: slot(self.mocap_pos(), m.0),
            quat: slot(self.mocap_quat(), m.0),
        }
    }

    /// Sets mocap slot `m`'s pose.
    pub fn set_mocap_pose(&mut self, m: MocapId, pose: &Pose) {
        self.mocap_pos_mut()[3 * m.0..3 * m.0 + 3].copy_from_slice(&pose.pos);
        self.mocap_quat_mut()[4 * m.0..4 * m.0 + 4].copy_from_slice(&pose.quat);
    }

    /// Sets the force and torque applied to body `b` at its centre of mass, in world
    /// coordinates (`xfrc_applied`: force, then torque).
    pub fn set_body_wrench(&mut self, b: BodyId, wrench: [f64; 6]) {
        self.xfrc_applied_mut()[6 * b.0..6 * b.0 + 6].copy_from_slice(&wrench);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_round_trips_bitwise_through_its_stored_form_and_isometry() {
        // A quaternion that is not exactly unit keeps its bits (no renormalisation).
        let v = [0.1, -0.2, 0.3, 0.6, 0.0, 0.0, 0.8000000000000002];
        let p = Pose::from_array(v);
        assert_eq!(p.to_array(), v);
        assert_eq!(Pose::from_slice(&v).unwrap(), p);
        assert_eq!(Pose::from_slice(&v[..6]), None);
        assert_eq!(Pose::from_isometry(&p.isometry()).to_array(), v);
        assert_eq!(p.position(), Vector3::new(0.1, -0.2, 0.3));
    }

    #[test]
    fn slots_read_the_objects_own_numbers() {
        let flat = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(slot::<f64, 3>(&flat, 1), [3.0, 4.0, 5.0]);
        assert_eq!(BodyId::from_index(4).index(), 4);
    }
}
