//! The robot description: a robot read from URDF (with urdf-rs) and SRDF (the "Default"
//! collision exclusions) into a [`RobotDesc`], and its joints' PD [`Drive`]s. The controllers
//! (kinematics, drives) and the MJCF writer, which consumes it, share it.
//!
//! Loader rules follow ManiSkill/SAPIEN (docs/robots.md §1.1): joint order is breadth-first over
//! the kinematic tree with siblings in URDF declaration order; `continuous` joints are
//! unlimited revolute joints; fixed links stay separate links.
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

/// Errors while reading a robot description; the text names the file and the problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotError {
    /// The URDF could not be parsed.
    #[error("malformed URDF {file}: {msg}")]
    Urdf {
        /// File name.
        file: String,
        /// Parser message.
        msg: String,
    },
    /// The SRDF could not be parsed.
    #[error("malformed SRDF {file}: {msg}")]
    Srdf {
        /// File name.
        file: String,
        /// Parser message.
        msg: String,
    },
    /// The URDF is well-formed XML but not a valid robot tree.
    #[error("invalid robot {file}: {msg}")]
    Structure {
        /// File name.
        file: String,
        /// What is wrong.
        msg: String,
    },
}

/// Joint kinds (URDF types).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Limited revolute joint.
    Revolute,
    /// Unlimited revolute joint.
    Continuous,
    /// Prismatic joint.
    Prismatic,
    /// Fixed joint (no dof).
    Fixed,
}

/// A geometric shape of a link (collision or visual).
#[derive(Debug, Clone, PartialEq)]
pub enum ShapeGeom {
    /// Box with half extents.
    Box([f64; 3]),
    /// Cylinder along local z: radius, half length.
    Cylinder(f64, f64),
    /// Capsule along local z: radius, half length of the cylindrical part.
    Capsule(f64, f64),
    /// Sphere radius.
    Sphere(f64),
    /// Mesh file (path as written in the URDF) and scale.
    Mesh(String, [f64; 3]),
}

/// A shape with its pose in the link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// Pose in the link frame.
    pub origin: Isometry3<f64>,
    /// The geometry.
    pub geom: ShapeGeom,
    /// Colour (visuals with a material colour).
    pub rgba: Option<[f64; 4]>,
    /// Texture image file (visuals whose material names one), as written in the URDF.
    pub texture: Option<String>,
}

/// Mass properties of a link, expressed in the link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Inertial {
    /// Mass in kg.
    pub mass: f64,
    /// Centre of mass in the link frame.
    pub com: Vector3<f64>,
    /// Full inertia tensor about the COM, in link-frame axes.
    pub inertia: Matrix3<f64>,
}

/// One link.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkDesc {
    /// Link name.
    pub name: String,
    /// URDF inertial, if any (with mass > 0).
    pub inertial: Option<Inertial>,
    /// Collision shapes.
    pub collisions: Vec<Shape>,
    /// Visual shapes.
    pub visuals: Vec<Shape>,
}

/// URDF `<mimic>`: this joint follows `leader`: q = multiplier · q_leader + offset.
#[derive(Debug, Clone, PartialEq)]
pub struct Mimic {
    /// The joint being followed.
    pub leader: String,
    /// Multiplier.
    pub multiplier: f64,
    /// Offset.
    pub offset: f64,
}

/// One joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointDesc {
    /// Joint name.
    pub name: String,
    /// Kind.
    pub kind: JointKind,
    /// Parent link index.
    pub parent: usize,
    /// Child link index.
    pub child: usize,
    /// Pose of the child frame in the parent frame at q = 0.
    pub origin: Isometry3<f64>,
    /// Unit axis in the child frame.
    pub axis: Vector3<f64>,
    /// Position limits (−inf, inf for continuous).
    pub limits: (f64, f64),
    /// Mimic relation, if any.
    pub mimic: Option<Mimic>,
}

/// A parsed robot.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotDesc {
    /// Robot name.
    pub name: String,
    /// Links in URDF order.
    pub links: Vec<LinkDesc>,
    /// Joints in URDF order.
    pub joints: Vec<JointDesc>,
    /// Root link index.
    pub root: usize,
    /// SRDF `<disable_collisions reason="Default">` pairs (link names).
    pub disabled_pairs: Vec<(String, String)>,
}

/// A PD drive on one joint (docs/controllers.md §5).
#[derive(Debug, Clone, PartialEq)]
pub struct Drive {
    /// Joint name.
    pub joint: String,
    /// Stiffness (N/m or N·m/rad).
    pub kp: f64,
    /// Damping.
    pub kd: f64,
    /// Force limit (N or N·m).
    pub force_limit: f64,
}

/// Name of the actuator that drives `joint`.
pub fn actuator_name(joint: &str) -> String {
    format!("drive_{joint}")
}

/// URDF roll-pitch-yaw (fixed axes x, y, z) plus translation as an isometry.
pub fn pose_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    pose_from_xyz_rpy(*p.xyz, *p.rpy)
}

fn shape(
    origin: &urdf_rs::Pose,
    g: &urdf_rs::Geometry,
    rgba: Option<[f64; 4]>,
    file: &str,
) -> Result<Shape, RobotError> {
    let bad = |msg: String| RobotError::Structure {
        file: file.to_string(),
        msg,
    };
    let positive = |what: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(bad(format!("{what} must be positive, got {v}")))
        }
    };
    let geom = match g {
        urdf_rs::Geometry::Box { size } => ShapeGeom::Box([
            positive("box size", size[0])? / 2.0,
            positive("box size", size[1])? / 2.0,
            positive("box size", size[2])? / 2.0,
        ]),
        urdf_rs::Geometry::Cylinder { radius, length } => ShapeGeom::Cylinder(
            positive("cylinder radius", *radius)?,
            positive("cylinder length", *length)? / 2.0,
        ),
        urdf_rs::Geometry::Capsule { radius, length } => ShapeGeom::Capsule(
            positive("capsule radius", *radius)?,
            positive("capsule length", *length)? / 2.0,
        ),
        urdf_rs::Geometry::Sphere { radius } => {
            ShapeGeom::Sphere(positive("sphere radius", *radius)?)
        }
        urdf_rs::Geometry::Mesh { filename, scale } => ShapeGeom::Mesh(
            filename.clone(),
            scale.map(|s| *s).unwrap_or([1.0, 1.0, 1.0]),
        ),
    };
    Ok(Shape {
        origin: pose(origin),
        geom,
        rgba,
        texture: None,
    })
}

/// The visual shapes of every link of a URDF document, in document order (used for scene
/// models such as the table, which are one link without joints). `file` names it in errors.
pub fn visuals_of(urdf: &str, file: &str) -> Result<Vec<Shape>, RobotError> {
    let robot = urdf_rs::read_from_string(urdf).map_err(|e| RobotError::Urdf {
        file: file.to_string(),
        msg: e.to_string(),
    })?;
    let mut out = Vec::new();
    for l in &robot.links {
        for v in &l.visual {
            let m = v.material.as_ref();
            let mut s = shape(
                &v.origin,
                &v.geometry,
                m.and_then(|m| m.color.as_ref()).map(|c| *c.rgba),
                file,
            )?;
            s.texture = m
                .and_then(|m| m.texture.as_ref())
                .map(|t| t.filename.clone());
            out.push(s);
        }
    }
    Ok(out)
}

/// One URDF link: inertia (rotated into the link frame), collision and visual shapes.
fn link_desc(l: &urdf_rs::Link, file: &str) -> Result<LinkDesc, RobotError> {
    let i = &l.inertial;
    let ixx = &i.inertia;
    let inertial = if i.mass.value > 0.0 {
        let r = pose(&i.origin).rotation.to_rotation_matrix();
        let local = Matrix3::new(
            ixx.ixx, ixx.ixy, ixx.ixz, //
            ixx.ixy, ixx.iyy, ixx.iyz, //
            ixx.ixz, ixx.iyz, ixx.izz,
        );
        Some(Inertial {
            mass: i.mass.value,
            com: Vector3::from(*i.origin.xyz),
            inertia: r.matrix() * local * r.matrix().transpose(),
        })
    } else {
        None
    };
    let mut collisions = Vec::new();
    for c in &l.collision {
        collisions.push(shape(&c.origin, &c.geometry, None, file)?);
    }
    let mut visuals = Vec::new();
    for v in &l.visual {
        let rgba = v
            .material
            .as_ref()
            .and_then(|m| m.color.as_ref())
            .map(|c| *c.rgba);
        let mut s = shape(&v.origin, &v.geometry, rgba, file)?;
        s.texture = v
            .material
            .as_ref()
            .and_then(|m| m.texture.as_ref())
            .map(|t| t.filename.clone());
        visuals.push(s);
    }
    Ok(LinkDesc {
        name: l.name.clone(),
        inertial,
        collisions,
        visuals,
    })
}

/// One URDF joint (`link_index`: a link's index by name; `bad`: a structure error).
fn joint_desc(
    j: &urdf_rs::Joint,
    link_index: &dyn Fn(&str) -> Result<usize, RobotError>,
    bad: &dyn Fn(String) -> RobotError,
) -> Result<JointDesc, RobotError> {
    let kind = match j.joint_type {
        urdf_rs::JointType::Revolute => JointKind::Revolute,
        urdf_rs::JointType::Continuous => JointKind::Continuous,
        urdf_rs::JointType::Prismatic => JointKind::Prismatic,
        urdf_rs::JointType::Fixed => JointKind::Fixed,
        ref other => {
            return Err(bad(format!(
                "joint {:?} has unsupported type {other:?} (supported: revolute, continuous, prismatic, fixed)",
                j.name
            )))
        }
    };
    let axis = Vector3::from(*j.axis.xyz);
    let axis = if kind == JointKind::Fixed {
        Vector3::z()
    } else {
        let n = axis.norm();
        if !(n.is_finite() && n > 1e-9) {
            return Err(bad(format!("joint {:?} has a zero axis", j.name)));
        }
        axis / n
    };
    let limits = match kind {
        JointKind::Continuous => (f64::NEG_INFINITY, f64::INFINITY),
        JointKind::Fixed => (0.0, 0.0),
        _ => {
            if j.limit.lower > j.limit.upper {
                return Err(bad(format!(
                    "joint {:?} has lower limit {} above upper limit {}",
                    j.name, j.limit.lower, j.limit.upper
                )));
            }
            (j.limit.lower, j.limit.upper)
        }
    };
    let mimic = j.mimic.as_ref().map(|m| Mimic {
        leader: m.joint.clone(),
        multiplier: m.multiplier.unwrap_or(1.0),
        offset: m.offset.unwrap_or(0.0),
    });
    Ok(JointDesc {
        name: j.name.clone(),
        kind,
        parent: link_index(&j.parent.link)?,
        child: link_index(&j.child.link)?,
        origin: pose(&j.origin),
        axis,
        limits,
        mimic,
    })
}

impl RobotDesc {
    /// Parses a URDF document and (optionally) its SRDF. `file` names the URDF in errors.
    pub fn parse(urdf: &str, srdf: Option<&str>, file: &str) -> Result<RobotDesc, RobotError> {
        let robot = urdf_rs::read_from_string(urdf).map_err(|e| RobotError::Urdf {
            file: file.to_string(),
            msg: e.to_string(),
        })?;
        let bad = |msg: String| RobotError::Structure {
            file: file.to_string(),
            msg,
        };
        let links = robot
            .links
            .iter()
            .map(|l| link_desc(l, file))
            .collect::<Result<Vec<_>, _>>()?;
        let link_index = |name: &str| {
            links
                .iter()
                .position(|l| l.name == name)
                .ok_or_else(|| bad(format!("joint refers to unknown link {name:?}")))
        };
        let joints = robot
            .joints
            .iter()
            .map(|j| joint_desc(j, &link_index, &bad))
            .collect::<Result<Vec<_>, _>>()?;
        // Tree checks: every link but one has exactly one parent joint.
        let mut parent_count = vec![0usize; links.len()];
        for j in &joints {
            parent_count[j.child] += 1;
        }
        if let Some(i) = parent_count.iter().position(|&c| c > 1) {
            return Err(bad(format!(
                "link {:?} has more than one parent joint",
                links[i].name
            )));
        }
        let roots: Vec<usize> = (0..links.len()).filter(|&i| parent_count[i] == 0).collect();
        if roots.len() != 1 {
            let names: Vec<&str> = roots.iter().map(|&i| links[i].name.as_str()).collect();
            return Err(bad(format!(
                "expected exactly one root link, found {names:?}"
            )));
        }
        for j in &joints {
            if let Some(m) = &j.mimic {
                if !joints.iter().any(|k| k.name == m.leader) {
                    return Err(bad(format!(
                        "joint {:?} mimics unknown joint {:?}",
                        j.name, m.leader
                    )));
                }
            }
        }
        let disabled_pairs = match srdf {
            Some(text) => parse_srdf_default_pairs(text, &file.replace(".urdf", ".srdf"))?,
            None => Vec::new(),
        };
        let desc = RobotDesc {
            name: robot.name.clone(),
            links,
            joints,
            root: roots[0],
            disabled_pairs,
        };
        if desc.bfs_joint_order().len() != desc.joints.len() {
            return Err(bad(
                "the kinematic tree has a cycle or unreachable joints".into()
            ));
        }
        Ok(desc)
    }

    /// Index of the link with this name.
    pub fn link(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// Index of the joint with this name.
    pub fn joint(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The joint whose child is `link`, if any.
    pub fn parent_joint(&self, link: usize) -> Option<usize> {
        self.joints.iter().position(|j| j.child == link)
    }

    /// Child joints of a link, in URDF declaration order.
    pub fn child_joints(&self, link: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .enumerate()
            .filter(move |(_, j)| j.parent == link)
            .map(|(i, _)| i)
    }

    /// All joints in breadth-first order from the root (siblings in declaration order).
    pub fn bfs_joint_order(&self) -> Vec<usize> {
        let mut order = Vec::new();
        let mut queue = std::collections::VecDeque::from([self.root]);
        let mut seen = vec![false; self.links.len()];
        while let Some(l) = queue.pop_front() {
            if std::mem::replace(&mut seen[l], true) {
                continue;
            }
            for j in self.child_joints(l) {
                order.push(j);
                queue.push_back(self.joints[j].child);
            }
        }
        order
    }

    /// The active (non-fixed) joints in ManiSkill's qpos order (breadth-first).
    pub fn active_joints(&self) -> Vec<usize> {
        self.bfs_joint_order()
            .into_iter()
            .filter(|&j| self.joints[j].kind != JointKind::Fixed)
            .collect()
    }

    /// Forward kinematics: world-from-link pose of every link for the active-joint values
    /// `q` (ManiSkill order, as [`RobotDesc::active_joints`]), with the root at `base`.
    pub fn forward_kinematics(&self, base: &Isometry3<f64>, q: &[f64]) -> Vec<Isometry3<f64>> {
        let active = self.active_joints();
        assert_eq!(q.len(), active.len(), "q needs one value per active joint");
        let mut value = vec![0.0; self.joints.len()];
        for (k, &j) in active.iter().enumerate() {
            value[j] = q[k];
        }
        let mut poses = vec![Isometry3::identity(); self.links.len()];
        poses[self.root] = *base;
        for j in self.bfs_joint_order() {
            let jd = &self.joints[j];
            let motion = match jd.kind {
                JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_axis_angle(
                        &nalgebra::Unit::new_normalize(jd.axis),
                        value[j],
                    ),
                ),
                JointKind::Prismatic => Isometry3::from_parts(
                    Translation3::from(jd.axis * value[j]),
                    UnitQuaternion::identity(),
                ),
                JointKind::Fixed => Isometry3::identity(),
            };
            poses[jd.child] = poses[jd.parent] * jd.origin * motion;
        }
        poses
    }
}

/// The `<disable_collisions link1 link2 reason="Default"/>` pairs of an SRDF (reason compared
/// case-insensitively; other reasons are ignored, as SAPIEN's loader does).
pub fn parse_srdf_default_pairs(
    text: &str,
    file: &str,
) -> Result<Vec<(String, String)>, RobotError> {
    let doc = roxmltree::Document::parse(text).map_err(|e| RobotError::Srdf {
        file: file.into(),
        msg: e.to_string(),
    })?;
    let mut pairs = Vec::new();
    for n in doc
        .descendants()
        .filter(|n| n.has_tag_name("disable_collisions"))
    {
        let reason = n.attribute("reason").unwrap_or("");
        if !reason.eq_ignore_ascii_case("default") {
            continue;
        }
        match (n.attribute("link1"), n.attribute("link2")) {
            (Some(a), Some(b)) => pairs.push((a.to_string(), b.to_string())),
            _ => {
                return Err(RobotError::Srdf {
                    file: file.into(),
                    msg: "disable_collisions needs link1 and link2".into(),
                })
            }
        }
    }
    Ok(pairs)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_LINK: &str = r#"<robot name="t">
      <link name="a"/><link name="b"><inertial><mass value="1"/><origin xyz="0 0 0.1" rpy="0 0 1.5707963267948966"/>
        <inertia ixx="1" iyy="2" izz="3" ixy="0" ixz="0" iyz="0"/></inertial>
        <collision><geometry><box size="0.2 0.4 0.6"/></geometry></collision></link>
      <link name="c"/><link name="d"/>
      <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 1"/><axis xyz="0 0 2"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
      <joint name="j2" type="prismatic"><parent link="b"/><child link="c"/><axis xyz="1 0 0"/>
        <limit lower="0" upper="0.5" effort="1" velocity="1"/><mimic joint="j1" multiplier="2" offset="0.1"/></joint>
      <joint name="j3" type="continuous"><parent link="a"/><child link="d"/><axis xyz="0 1 0"/></joint>
    </robot>"#;

    #[test]
    fn parses_tree_bfs_mimic_and_rotated_inertia() {
        let r = RobotDesc::parse(TWO_LINK, None, "t.urdf").unwrap();
        assert_eq!(r.root, 0);
        let names: Vec<&str> = r
            .active_joints()
            .iter()
            .map(|&j| r.joints[j].name.as_str())
            .collect();
        assert_eq!(names, ["j1", "j3", "j2"], "breadth-first order");
        let j2 = &r.joints[r.joint("j2").unwrap()];
        assert_eq!(j2.mimic.as_ref().unwrap().multiplier, 2.0);
        assert_eq!(r.joints[0].axis, Vector3::z(), "axis normalised");
        assert!(r.joints[2].limits.1.is_infinite());
        let i = r.links[1].inertial.as_ref().unwrap();
        // rotated by 90° about z: ixx and iyy swap
        assert!((i.inertia[(0, 0)] - 2.0).abs() < 1e-12 && (i.inertia[(1, 1)] - 1.0).abs() < 1e-12);
        assert_eq!(
            r.links[1].collisions[0].geom,
            ShapeGeom::Box([0.1, 0.2, 0.3])
        );
        let fk = r.forward_kinematics(&Isometry3::identity(), &[0.0, 0.0, 0.25]);
        assert!((fk[2].translation.vector - Vector3::new(0.25, 0.0, 1.0)).norm() < 1e-12);
    }

    #[test]
    fn malformed_urdf_is_an_error_naming_the_file() {
        let e = RobotDesc::parse("<robot name='x'><link name='a'/><joint", None, "bad.urdf")
            .unwrap_err();
        assert!(e.to_string().contains("bad.urdf"), "{e}");
        let e = RobotDesc::parse(
            &TWO_LINK.replace("<parent link=\"b\"/>", "<parent link=\"zz\"/>"),
            None,
            "t.urdf",
        )
        .unwrap_err();
        assert!(e.to_string().contains("zz"), "{e}");
        let e = RobotDesc::parse(
            &TWO_LINK.replace("0.2 0.4 0.6", "0.2 -0.4 0.6"),
            None,
            "t.urdf",
        )
        .unwrap_err();
        assert!(e.to_string().contains("positive"), "{e}");
    }

    #[test]
    fn srdf_keeps_only_default_pairs() {
        let s = r#"<robot name="t"><disable_collisions link1="a" link2="b" reason="Default"/>
          <disable_collisions link1="a" link2="c" reason="Adjacent"/><disable_collisions link1="c" link2="d" reason="DEFAULT"/></robot>"#;
        let p = parse_srdf_default_pairs(s, "t.srdf").unwrap();
        assert_eq!(
            p,
            vec![
                ("a".to_string(), "b".to_string()),
                ("c".to_string(), "d".to_string())
            ]
        );
        assert!(parse_srdf_default_pairs("<robot", "t.srdf").is_err());
    }
}
