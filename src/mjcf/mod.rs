//! MJCF generation: robot URDFs (read by [`urdf`]) and task props ([`props`]) become one
//! MuJoCo scene ([`Scene`] → [`Mjcf`]), compiled by the safe layer.
//!
//! Physics scheme (see docs/physics.md for the reasoning, docs/agreement.md for the measurements):
//! * `timestep` chosen by the env (default [`TIMESTEP`], ManiSkill's 0.01 s) with MuJoCo's
//!   explicit Euler integrator; one 20 Hz control step is [`CONTROL_DT`] / timestep physics
//!   steps.
//! * Every controlled joint gets a force actuator (`motor`, force range ±F); the env computes
//!   PhysX's implicit, force-clamped PD drive law every substep (`controllers::drive`).
//! * Robot links do not feel gravity (ManiSkill disables it on them). MuJoCo 2.2 has no
//!   per-body gravity switch, so the scene's gravity is switched off (`<flag gravity=
//!   "disable"/>`; `gravity` keeps ManiSkill's value) and the env applies `m·g` downward at the
//!   centre of mass of every body that moves and is not the robot's, through `xfrc_applied`:
//!   one or two props instead of every robot link (docs/speed.md, "Cuts").
//! * Friction: every shape has ManiSkill's default material μ = 0.3; shapes with their own
//!   material (finger pads, μ = 2.0) get the PhysX *average* with the default, because
//!   MuJoCo combines by *max* and every partner of a finger has μ = 0.3.
pub mod props;
/// The robot description the writer reads (defined with the controllers, which share it).
pub use crate::controllers::desc as urdf;
pub use crate::controllers::desc::{actuator_name, Drive};
pub mod xml;

use nalgebra::Isometry3;

use crate::mujoco::{BodyId, Data, Model, Result as MjResult};
use urdf::{JointKind, RobotDesc, ShapeGeom};
use xml::{num, nums, Element};

/// Why a robot could not be added to a scene: its options name something the robot lacks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SceneError {
    /// A drive or armature names a joint the robot does not have.
    #[error("robot {robot} has no joint {joint:?}")]
    NoJoint {
        /// The robot.
        robot: String,
        /// The joint.
        joint: String,
    },
    /// A site is attached to a link the robot does not have.
    #[error("robot {robot} has no link {link:?} for a site")]
    NoSiteLink {
        /// The robot.
        robot: String,
        /// The link.
        link: String,
    },
    /// A camera is attached to a link the robot does not have.
    #[error("robot {robot} has no link {link:?} for camera {camera:?}")]
    NoCameraLink {
        /// The robot.
        robot: String,
        /// The link.
        link: String,
        /// The camera.
        camera: String,
    },
    /// A collision exclusion names a link the robot does not have.
    #[error("collision exclusion names unknown link {0:?} or {1:?}")]
    UnknownExcludedLink(String, String),
    /// A link without ground contact is not one of the robot's.
    #[error("robot {robot} has no link {link:?}")]
    NoLink {
        /// The robot.
        robot: String,
        /// The link.
        link: String,
    },
    /// A URDF mesh file could not be resolved.
    #[error("mesh file {0:?} not found")]
    MeshNotFound(String),
}

/// Default physics timestep in seconds, ManiSkill's (the env's `SimConfig` may choose
/// another).
pub const TIMESTEP: f64 = 0.01;
/// ManiSkill's control frequency (Hz): one env step is 1/20 s.
pub const CONTROL_FREQ: u32 = 20;
/// Control period of one env step in seconds, `1 / CONTROL_FREQ` (0.05).
pub const CONTROL_DT: f64 = 1.0 / CONTROL_FREQ as f64;
/// Standard gravity used by ManiSkill.
pub const GRAVITY: f64 = 9.81;
/// ManiSkill's default material friction (static = dynamic).
pub const DEFAULT_FRICTION: f64 = 0.3;
/// MuJoCo torsional and rolling friction coefficients used for every geom.
pub const TORSIONAL_ROLLING: [f64; 2] = [0.005, 0.0001];
/// Constraint `solref` (time constant, damping ratio) of contacts and of the stiff
/// equalities: the stiffest stable setting at timestep `dt` (time constant 2·dt), so that
/// rigid PhysX-like contacts are approximated and a grasped 4 cm cube is penetrated by well
/// under a millimetre.
pub fn stiff_solref(dt: f64) -> [f64; 2] {
    [2.0 * dt, 1.0]
}
/// Contact `solimp`: impedance 0.99 at first touch rising to 0.9999 over 1 mm of
/// penetration. At a 0.01 s step the time constant cannot go below 0.02 s, so the contact
/// is made hard through the impedance instead: a 100 N grasp sinks ~0.1 mm into the cube.
pub const CONTACT_SOLIMP: [f64; 3] = [0.99, 0.9999, 0.001];
/// Contact `solimp` of [`RobotOptions::firm_contact`] links: impedance 0.999 from first
/// touch, so that a grasp with little normal force (the xArm6's 0.1 N·m gripper) creeps
/// ten times slower than with [`CONTACT_SOLIMP`].
pub const FIRM_CONTACT_SOLIMP: [f64; 3] = [0.999, 0.9999, 0.001];
/// Contact margin (m). MuJoCo only enforces contacts strictly closer than the margin; with
/// a zero margin a cube placed exactly on the table (as ManiSkill places it) falls freely
/// through its first substep. One micrometre makes the touching contact count.
pub const CONTACT_MARGIN: f64 = 1e-6;
/// Constraint rows MuJoCo preallocates per `mjData` (contacts × condim plus limits and
/// equalities). The tabletop scenes use well under 200; keeping `mjData` small keeps many
/// envs in cache (VecEnv). Overflow is reported as a MuJoCo warning in `info.warnings`.
pub const NJMAX: usize = 300;
/// Contacts MuJoCo preallocates per `mjData`.
pub const NCONMAX: usize = 100;
/// Density of every prop and of robot links without URDF inertials (kg/m³).
pub const DENSITY: f64 = 1000.0;
/// Mass and principal inertia SAPIEN gives a link with neither inertial nor shapes.
pub const MASSLESS: f64 = 1e-6;
/// Geom group of robot visual shapes.
pub const GROUP_ROBOT_VISUAL: i32 = 1;
/// Geom group of visual-only markers hidden from sensor cameras (e.g. PickCube's goal).
pub const GROUP_HIDDEN: i32 = 2;
/// Geom group of robot collision shapes (not drawn).
pub const GROUP_COLLISION: i32 = 3;

/// A compiled-ready MJCF document plus the in-memory asset files it references.
#[derive(Debug, Clone, PartialEq)]
pub struct Mjcf {
    /// The MJCF XML text.
    pub xml: String,
    /// (file name, bytes) of meshes referenced by the XML.
    pub assets: Vec<(String, Vec<u8>)>,
}

impl Mjcf {
    /// Compiles the document with MuJoCo; its `mjData` stack is sized by
    /// [`Model::shrink_stack`] (about 0.4 MB instead of the compiler's 4 MB per env).
    pub fn compile(&self) -> MjResult<Model> {
        let assets: Vec<(&str, &[u8])> = self
            .assets
            .iter()
            .map(|(n, b)| (n.as_str(), b.as_slice()))
            .collect();
        let mut model = Model::from_xml_string(&self.xml, &assets)?;
        model.shrink_stack();
        Ok(model)
    }
}

/// A ball-joint loop closure between two links (MuJoCo `<equality><connect>`).
#[derive(Debug, Clone, PartialEq)]
pub struct Connect {
    /// First link.
    pub link1: String,
    /// Second link.
    pub link2: String,
    /// Anchor in the first link's frame (coincides with the second link's anchor).
    pub anchor: [f64; 3],
}

/// A MuJoCo camera in a robot link's body.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkCamera {
    /// Camera name.
    pub name: String,
    /// The link (body) it is attached to.
    pub link: String,
    /// Position in the link frame.
    pub pos: [f64; 3],
    /// Orientation (w, x, y, z) of the MuJoCo camera frame (looking along −z, +y up) in the
    /// link frame.
    pub quat: [f64; 4],
    /// Vertical field of view in degrees.
    pub fovy_deg: f64,
}

/// How a robot is placed and driven in a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotOptions {
    /// Pose of the root link in the world.
    pub base: Isometry3<f64>,
    /// PD drives (one actuator each, in this order).
    pub drives: Vec<Drive>,
    /// Armature added to every joint not listed in `armature`.
    pub default_armature: f64,
    /// Per-joint armature.
    pub armature: Vec<(String, f64)>,
    /// Per-joint passive damping (undriven joints, e.g. mimic followers without a drive).
    pub damping: Vec<(String, f64)>,
    /// Links whose collision shapes have their own material friction (PhysX value).
    pub material_friction: Vec<(String, f64)>,
    /// Sites: (site name, link, position in the link frame).
    pub sites: Vec<(String, String, [f64; 3])>,
    /// Link pairs excluded from contact in addition to the SRDF's.
    pub extra_excludes: Vec<(String, String)>,
    /// Links that never collide with the ground plane (e.g. Fetch's wheels).
    pub no_ground_contact: Vec<String>,
    /// Links that cannot reach the table or the floor at any joint position: their contacts
    /// with the world body's geoms are excluded, which spares the broad phase those pairs
    /// (docs/speed.md, "Cuts").
    pub clear_of_world: Vec<String>,
    /// Loop closures.
    pub connects: Vec<Connect>,
    /// Whether the joint equalities made from URDF `<mimic>` tags get [`stiff_solref`] and
    /// the contacts' hard impedance [`CONTACT_SOLIMP`] (otherwise MuJoCo's defaults). The stiff value stands in for PhysX's 1e5 N/m
    /// mimic tendon where a mimic follower has no drive of its own (WidowX AI).
    pub stiff_mimic: bool,
    /// Links whose collision shapes get torsional friction (condim 4) with this coefficient
    /// (m): MuJoCo's analogue of a PhysX material `patch_radius` (torque ≤ μ·r·N).
    pub torsional_friction: Vec<(String, f64)>,
    /// Whether the loop closures get [`stiff_solref`] and [`CONTACT_SOLIMP`] (otherwise
    /// MuJoCo's defaults).
    pub stiff_connect: bool,
    /// Cameras attached to links.
    pub cameras: Vec<LinkCamera>,
    /// Links whose contacts get the firmer impedance [`FIRM_CONTACT_SOLIMP`] (dominating
    /// the partner's through `solmix`): weak grippers whose light grasp would otherwise
    /// creep under MuJoCo's soft friction.
    pub firm_contact: Vec<String>,
    /// Links whose contacts get their own impedance `solimp` (dominating the partner's
    /// through `solmix`), with the default time constant: PhysX's yielding grip of the SO100's
    /// jaws, which sink into what they squeeze (docs/outcome-physics.md).
    pub contact_solimp: Vec<(String, [f64; 3])>,
    /// Penetration (m) at which the links a gripper joint moves let go of an object they
    /// have sunk into ([`crate::controllers::Drives`]); `None`: never.
    pub gripper_release_depth: Option<f64>,
    /// MuJoCo's no-slip pass in every scene with this robot ([`Scene::set_noslip_iterations`];
    /// 0: none): a gripper whose grasp PhysX holds rigidly while MuJoCo's soft friction lets the
    /// held object turn (the WidowX AI, docs/outcome-physics.md).
    pub noslip_iterations: u32,
}

impl Default for RobotOptions {
    fn default() -> Self {
        RobotOptions {
            base: Isometry3::identity(),
            drives: Vec::new(),
            default_armature: 0.0,
            armature: Vec::new(),
            damping: Vec::new(),
            material_friction: Vec::new(),
            sites: Vec::new(),
            extra_excludes: Vec::new(),
            no_ground_contact: Vec::new(),
            clear_of_world: Vec::new(),
            connects: Vec::new(),
            stiff_mimic: false,
            stiff_connect: false,
            torsional_friction: Vec::new(),
            cameras: Vec::new(),
            firm_contact: Vec::new(),
            contact_solimp: Vec::new(),
            gripper_release_depth: None,
            noslip_iterations: 0,
        }
    }
}

// Collision bits (contype = conaffinity for every geom): 1 = general, 2 = ground,
// 4 = table top plane (props only), 8 = table box (robots only). Two geoms collide when
// they share a bit. The table top is split this way because MuJoCo 2.2's box–box collider
// produces bogus metre-deep contacts between small boxes (the 4 cm cube) and the 2.4 m
// table box; props meet an infinite plane at z = 0 instead, robots keep the box.

/// Bits of props and kinematic obstacles: general, ground and the table-top plane.
pub const CONTACT_PROP: i32 = 1 | 2 | 4;
/// Bits of robot collision geoms: general, ground and the table box.
pub const CONTACT_ROBOT: i32 = 1 | 2 | 8;
/// Bits of robot geoms that ignore the ground (Fetch's wheels).
pub const CONTACT_NOT_GROUND: i32 = 1 | 8;
/// Bits of the ground plane.
pub const CONTACT_GROUND: i32 = 2;
/// Bits of the table-top plane (props only).
pub const CONTACT_TABLE_PLANE: i32 = 4;
/// Bits of the table box (robots only).
pub const CONTACT_TABLE_BOX: i32 = 8;

/// Name of the ground plane geom.
pub const GROUND: &str = "ground";
/// Name of the table geom.
pub const TABLE: &str = "table-workspace";

/// The weights (m·g, N) of the bodies of `model` that a joint moves, leaving out `robot`'s
/// (whose links ManiSkill keeps weightless) and bodies without mass. The scene's gravity is
/// switched off (module docs); [`apply_weights`] puts these back as applied forces.
pub fn prop_weights(model: &Model, robot: &[BodyId]) -> Vec<(BodyId, f64)> {
    let parent = model.body_parentid();
    let dofs = model.body_dofnum();
    // A body moves when it or a body above it has a dof; a static or mocap body carries no
    // weight anywhere.
    let moves = |mut b: usize| loop {
        if b == 0 {
            return false;
        }
        if dofs[b] > 0 {
            return true;
        }
        b = parent[b] as usize;
    };
    (1..model.nbody())
        .filter(|&b| model.body_mass()[b] > 0.0 && moves(b))
        .filter(|&b| !robot.iter().any(|r| r.index() == b))
        .map(|b| (BodyId::from_index(b), model.body_mass()[b] * GRAVITY))
        .collect()
}

/// Sets `xfrc_applied` to `weights` (each a downward force at the body's centre of mass, from
/// [`prop_weights`]) and to zero on every other body. It persists across steps.
pub fn apply_weights(data: &mut Data, weights: &[(BodyId, f64)]) {
    data.xfrc_applied_mut().fill(0.0);
    for &(b, w) in weights {
        data.set_body_wrench(b, [0.0, 0.0, -w, 0.0, 0.0, 0.0]);
    }
}

/// Converts a pose to MJCF `pos` and `quat` attributes.
pub fn pose_attrs(mut e: Element, p: &Isometry3<f64>) -> Element {
    let t = p.translation.vector;
    if t.norm() != 0.0 {
        e = e.attr_nums("pos", &[t.x, t.y, t.z]);
    }
    let q = p.rotation;
    if q.angle() != 0.0 {
        e = e.attr_nums("quat", &[q.w, q.i, q.j, q.k]);
    }
    e
}

/// Builds an MJCF scene.
#[derive(Debug, Clone)]
pub struct Scene {
    root: Element,
    assets: Vec<(String, Vec<u8>)>,
    timestep: f64,
    /// Mesh and texture assets already added: (source file, scale) → asset name.
    added: std::collections::HashMap<String, String>,
    /// The robot's finger links with their own material friction (PhysX value), as
    /// [`Scene::add_robot`] added them: the links [`Scene::add_finger_pairs`] pairs with an
    /// object.
    fingers: Vec<(String, f64)>,
}

impl Scene {
    /// An empty scene with mjskill's physics options at physics timestep `timestep` (s).
    pub fn new(model_name: &str, timestep: f64) -> Scene {
        let mut root = Element::new("mujoco").attr("model", model_name);
        root.push(
            Element::new("compiler")
                .attr("angle", "radian")
                .attr("inertiafromgeom", "auto")
                // PhysX accepts any positive principal inertia; MuJoCo rejects tensors that
                // break the triangle inequality (Fetch's fingers: 0.002, 0.0002, 0.0002) unless
                // asked to balance them (all three diagonal entries set to their mean).
                .attr("balanceinertia", "true"),
        );
        root.push(
            Element::new("option")
                .attr("timestep", num(timestep))
                // Explicit Euler: the drives are implicit in their own terms
                // (`controllers::drive`); constraints stay implicit in MuJoCo's solver.
                .attr("integrator", "Euler")
                // Dense constraint Jacobians: the drives read the equality rows.
                .attr("jacobian", "dense")
                .attr_nums("gravity", &[0.0, 0.0, -GRAVITY])
                // Gravity reaches the props alone, as `xfrc_applied` (module docs).
                .child(Element::new("flag").attr("gravity", "disable")),
        );
        root.push(
            Element::new("size")
                .attr("njmax", NJMAX)
                .attr("nconmax", NCONMAX),
        );
        root.push(
            Element::new("visual")
                .child(
                    Element::new("global")
                        .attr("offwidth", 640)
                        .attr("offheight", 640),
                )
                .child(Element::new("quality").attr("shadowsize", 0)),
        );
        let friction = [DEFAULT_FRICTION, TORSIONAL_ROLLING[0], TORSIONAL_ROLLING[1]];
        root.push(
            Element::new("default").child(
                Element::new("geom")
                    .attr_nums("friction", &friction)
                    .attr_nums("solref", &stiff_solref(timestep))
                    .attr_nums("solimp", &CONTACT_SOLIMP)
                    .attr("margin", num(CONTACT_MARGIN))
                    .attr("contype", CONTACT_PROP)
                    .attr("conaffinity", CONTACT_PROP),
            ),
        );
        root.push(Element::new("asset"));
        root.push(Element::new("worldbody"));
        Scene {
            root,
            assets: Vec::new(),
            timestep,
            added: std::collections::HashMap::new(),
            fingers: Vec::new(),
        }
    }

    /// The `<worldbody>` element.
    pub fn worldbody(&mut self) -> &mut Element {
        self.root.section("worldbody")
    }

    /// A top-level section (`asset`, `contact`, `equality`, `actuator`, ...), created if missing.
    pub fn section(&mut self, name: &str) -> &mut Element {
        self.root.section(name)
    }

    /// Adds a robot. `mesh_bytes` resolves a file name of the URDF (mesh or texture) to its
    /// bytes.
    pub fn add_robot(
        &mut self,
        robot: &RobotDesc,
        opts: &RobotOptions,
        mesh_bytes: &dyn Fn(&str) -> Option<Vec<u8>>,
    ) -> std::result::Result<(), SceneError> {
        for name in opts
            .drives
            .iter()
            .map(|d| &d.joint)
            .chain(opts.armature.iter().map(|a| &a.0))
        {
            if robot.joint(name).is_none() {
                return Err(SceneError::NoJoint {
                    robot: robot.name.clone(),
                    joint: name.clone(),
                });
            }
        }
        for (_, link, _) in &opts.sites {
            if robot.link(link).is_none() {
                return Err(SceneError::NoSiteLink {
                    robot: robot.name.clone(),
                    link: link.to_string(),
                });
            }
        }
        for c in &opts.cameras {
            if robot.link(&c.link).is_none() {
                return Err(SceneError::NoCameraLink {
                    robot: robot.name.clone(),
                    link: c.link.to_string(),
                    camera: c.name.to_string(),
                });
            }
        }
        let root_body = self.link_body(robot, robot.root, opts, mesh_bytes, &opts.base)?;
        self.worldbody().push(root_body);
        self.fingers.extend(opts.material_friction.iter().cloned());
        if opts.noslip_iterations > 0 {
            self.set_noslip_iterations(opts.noslip_iterations);
        }

        // Contact exclusions: every URDF parent–child pair (PhysX never collides a link with its
        // parent; MuJoCo's own parent filter skips bodies welded to the world, such as a fixed
        // robot root), SRDF "Default" pairs and robot-specific extras.
        let mut pairs: Vec<(String, String)> = robot
            .joints
            .iter()
            .map(|j| {
                (
                    robot.links[j.parent].name.clone(),
                    robot.links[j.child].name.clone(),
                )
            })
            .collect();
        pairs.extend(robot.disabled_pairs.iter().cloned());
        pairs.extend(opts.extra_excludes.iter().cloned());
        let mut seen = std::collections::HashSet::new();
        for (a, b) in pairs {
            let (Some(la), Some(lb)) = (robot.link(&a), robot.link(&b)) else {
                return Err(SceneError::UnknownExcludedLink(a, b));
            };
            let key = if a < b {
                (a.clone(), b.clone())
            } else {
                (b.clone(), a.clone())
            };
            if la == lb || !seen.insert(key) {
                continue;
            }
            self.section("contact")
                .push(Element::new("exclude").attr("body1", &a).attr("body2", &b));
        }
        for l in &opts.clear_of_world {
            if robot.link(l).is_none() {
                return Err(SceneError::UnknownExcludedLink("world".into(), l.clone()));
            }
            self.section("contact").push(
                Element::new("exclude")
                    .attr("body1", "world")
                    .attr("body2", l),
            );
        }
        // Mimic joints → joint equality q_follower = offset + multiplier · q_leader.
        for j in &robot.joints {
            if let Some(m) = &j.mimic {
                let mut eq = Element::new("joint")
                    .attr("name", format!("mimic_{}", j.name))
                    .attr("joint1", &j.name)
                    .attr("joint2", &m.leader)
                    .attr_nums("polycoef", &[m.offset, m.multiplier, 0.0, 0.0, 0.0]);
                if opts.stiff_mimic {
                    eq = eq
                        .attr_nums("solref", &stiff_solref(self.timestep))
                        .attr_nums("solimp", &CONTACT_SOLIMP);
                }
                self.section("equality").push(eq);
            }
        }
        for c in &opts.connects {
            let mut e = Element::new("connect")
                .attr("name", format!("loop_{}_{}", c.link1, c.link2))
                .attr("body1", &c.link1)
                .attr("body2", &c.link2)
                .attr_nums("anchor", &c.anchor);
            if opts.stiff_connect {
                e = e
                    .attr_nums("solref", &stiff_solref(self.timestep))
                    .attr_nums("solimp", &CONTACT_SOLIMP);
            }
            self.section("equality").push(e);
        }
        // The drive force itself is computed by `controllers::drive` every substep; the
        // actuator applies it, clamped to the drive's force limit.
        for d in &opts.drives {
            self.section("actuator").push(
                Element::new("motor")
                    .attr("name", actuator_name(&d.joint))
                    .attr("joint", &d.joint)
                    .attr("ctrllimited", "false")
                    .attr("forcelimited", "true")
                    .attr_nums("forcerange", &[-d.force_limit, d.force_limit]),
            );
        }
        for link in &opts.no_ground_contact {
            if robot.link(link).is_none() {
                return Err(SceneError::NoLink {
                    robot: robot.name.clone(),
                    link: link.to_string(),
                });
            }
        }
        Ok(())
    }

    fn link_body(
        &mut self,
        robot: &RobotDesc,
        link: usize,
        opts: &RobotOptions,
        mesh_bytes: &dyn Fn(&str) -> Option<Vec<u8>>,
        pose: &Isometry3<f64>,
    ) -> std::result::Result<Element, SceneError> {
        let l = &robot.links[link];
        let mut body = pose_attrs(Element::new("body").attr("name", &l.name), pose);
        match &l.inertial {
            Some(i) => {
                let m = &i.inertia;
                body.push(
                    Element::new("inertial")
                        .attr_nums("pos", &[i.com.x, i.com.y, i.com.z])
                        .attr("mass", num(i.mass))
                        .attr_nums(
                            "fullinertia",
                            &[
                                m[(0, 0)],
                                m[(1, 1)],
                                m[(2, 2)],
                                m[(0, 1)],
                                m[(0, 2)],
                                m[(1, 2)],
                            ],
                        ),
                );
            }
            None if l.collisions.is_empty() => {
                body.push(
                    Element::new("inertial")
                        .attr("pos", "0 0 0")
                        .attr("mass", num(MASSLESS))
                        .attr_nums("diaginertia", &[MASSLESS; 3]),
                );
            }
            None => {} // MuJoCo computes it from the collision shapes at density 1000.
        }
        if let Some(j) = robot.parent_joint(link) {
            let jd = &robot.joints[j];
            if jd.kind != JointKind::Fixed {
                let mut je = Element::new("joint")
                    .attr("name", &jd.name)
                    .attr(
                        "type",
                        if jd.kind == JointKind::Prismatic {
                            "slide"
                        } else {
                            "hinge"
                        },
                    )
                    .attr_nums("axis", &[jd.axis.x, jd.axis.y, jd.axis.z]);
                if jd.kind == JointKind::Continuous {
                    je = je.attr("limited", "false");
                } else {
                    je = je
                        .attr("limited", "true")
                        .attr_nums("range", &[jd.limits.0, jd.limits.1]);
                }
                let arm = opts
                    .armature
                    .iter()
                    .find(|(n, _)| *n == jd.name)
                    .map(|a| a.1)
                    .unwrap_or(opts.default_armature);
                if arm > 0.0 {
                    je = je.attr("armature", num(arm));
                }
                if let Some((_, d)) = opts.damping.iter().find(|(n, _)| *n == jd.name) {
                    je = je.attr("damping", num(*d));
                }
                body.push(je);
            }
        }
        let friction = opts
            .material_friction
            .iter()
            .find(|(n, _)| *n == l.name)
            .map(|(_, mu)| (mu + DEFAULT_FRICTION) / 2.0);
        for (k, s) in l.collisions.iter().enumerate() {
            let mut g = self.shape_geom(s, &format!("{}_c{k}", l.name), mesh_bytes)?;
            g.set("name", collision_geom_name(&l.name, k));
            g.set("group", GROUP_COLLISION);
            g.set("rgba", "0.5 0.5 0.5 0.3");
            let bits = if opts.no_ground_contact.contains(&l.name) {
                CONTACT_NOT_GROUND
            } else {
                CONTACT_ROBOT
            };
            g.set("contype", bits);
            g.set("conaffinity", bits);
            let torsional = opts
                .torsional_friction
                .iter()
                .find(|(n, _)| *n == l.name)
                .map(|(_, t)| *t);
            if friction.is_some() || torsional.is_some() {
                let mu = friction.unwrap_or(DEFAULT_FRICTION);
                let t = torsional.unwrap_or(TORSIONAL_ROLLING[0]);
                g.set("friction", nums(&[mu, t, TORSIONAL_ROLLING[1]]));
            }
            if torsional.is_some() {
                g.set("condim", 4);
            }
            if opts.firm_contact.contains(&l.name) {
                g.set("solimp", nums(&FIRM_CONTACT_SOLIMP));
                g.set("solmix", 1000);
            }
            if let Some((_, imp)) = opts.contact_solimp.iter().find(|(n, _)| *n == l.name) {
                g.set("solimp", nums(imp));
                g.set("solmix", 1000);
            }
            body.push(g);
        }
        for (k, s) in l.visuals.iter().enumerate() {
            let name = format!("{}_visual{k}", l.name);
            let g = self.visual_geom(s, &name, GROUP_ROBOT_VISUAL, mesh_bytes)?;
            body.push(g);
        }
        for (name, site_link, p) in &opts.sites {
            if *site_link == l.name {
                body.push(
                    Element::new("site")
                        .attr("name", name)
                        .attr_nums("pos", p)
                        .attr("size", "0.005")
                        .attr("group", GROUP_HIDDEN),
                );
            }
        }
        for c in opts.cameras.iter().filter(|c| c.link == l.name) {
            body.push(
                Element::new("camera")
                    .attr("name", &c.name)
                    .attr_nums("pos", &c.pos)
                    .attr_nums("quat", &c.quat)
                    .attr("fovy", num(c.fovy_deg)),
            );
        }
        for j in robot.child_joints(link) {
            let jd = &robot.joints[j];
            let child = self.link_body(robot, jd.child, opts, mesh_bytes, &jd.origin)?;
            body.push(child);
        }
        Ok(body)
    }

    /// A drawn-only geom (no contacts, no mass) of `shape` named `name` in `group`, with its
    /// colour, or a material with its texture (resolved by `files` like a mesh).
    pub fn visual_geom(
        &mut self,
        s: &urdf::Shape,
        name: &str,
        group: i32,
        files: &dyn Fn(&str) -> Option<Vec<u8>>,
    ) -> std::result::Result<Element, SceneError> {
        let mut g = self.shape_geom(s, &format!("{name}_mesh"), files)?;
        g.set("name", name);
        g.set("group", group);
        g.set("contype", 0);
        g.set("conaffinity", 0);
        g.set("density", 0);
        match &s.texture {
            Some(file) => {
                let key = format!("texture {file}");
                let tex = match self.added.get(&key) {
                    Some(t) => t.clone(),
                    None => {
                        let bytes = files(file)
                            .ok_or_else(|| SceneError::MeshNotFound(file.to_string()))?;
                        let tex = format!("{name}_tex");
                        let vfs = format!("{tex}.png");
                        self.assets.push((vfs.clone(), bytes));
                        self.section("asset").push(
                            Element::new("texture")
                                .attr("name", &tex)
                                .attr("type", "2d")
                                .attr("file", &vfs),
                        );
                        self.added.insert(key, tex.clone());
                        tex
                    }
                };
                let mat = format!("{name}_mat");
                let mut m = Element::new("material")
                    .attr("name", &mat)
                    .attr("texture", &tex);
                if let Some(c) = s.rgba {
                    m = m.attr("rgba", nums(&c));
                }
                self.section("asset").push(m);
                g.set("material", mat);
            }
            None => {
                if let Some(c) = s.rgba {
                    g.set("rgba", nums(&c));
                }
            }
        }
        Ok(g)
    }

    fn shape_geom(
        &mut self,
        s: &urdf::Shape,
        mesh_name: &str,
        mesh_bytes: &dyn Fn(&str) -> Option<Vec<u8>>,
    ) -> std::result::Result<Element, SceneError> {
        let g = pose_attrs(Element::new("geom"), &s.origin);
        Ok(match &s.geom {
            ShapeGeom::Box(h) => g.attr("type", "box").attr_nums("size", h),
            ShapeGeom::Cylinder(r, hl) => g.attr("type", "cylinder").attr_nums("size", &[*r, *hl]),
            ShapeGeom::Capsule(r, hl) => g.attr("type", "capsule").attr_nums("size", &[*r, *hl]),
            ShapeGeom::Sphere(r) => g.attr("type", "sphere").attr_nums("size", &[*r]),
            ShapeGeom::Mesh(file, scale) => {
                let key = format!("mesh {file} {}", nums(scale));
                if let Some(name) = self.added.get(&key) {
                    return Ok(g.attr("type", "mesh").attr("mesh", name));
                }
                let bytes =
                    mesh_bytes(file).ok_or_else(|| SceneError::MeshNotFound(file.to_string()))?;
                let ext = file
                    .rsplit('.')
                    .next()
                    .unwrap_or("stl")
                    .to_ascii_lowercase();
                let vfs_name = format!("{mesh_name}.{ext}");
                self.assets.push((vfs_name.clone(), bytes));
                self.section("asset").push(
                    Element::new("mesh")
                        .attr("name", mesh_name)
                        .attr("file", &vfs_name)
                        .attr_nums("scale", scale),
                );
                self.added.insert(key, mesh_name.to_string());
                g.attr("type", "mesh").attr("mesh", mesh_name)
            }
        })
    }

    /// Runs MuJoCo's no-slip pass (`noslip_iterations`, 0 by default) after each step's
    /// constraint solve: a Gauss–Seidel pass over the friction rows without their softness,
    /// so that a contact whose friction can hold does not creep under a steady load (MuJoCo's
    /// soft friction otherwise slips at a rate proportional to it; PhysX's does not). A task
    /// that needs it asks for it in its scene, a robot in its [`RobotOptions`]; the scene
    /// keeps the larger of the counts asked for. docs/physics.md says which and why.
    pub fn set_noslip_iterations(&mut self, iterations: u32) {
        let option = self.root.section("option");
        let current = attr(option, "noslip_iterations")
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or(0);
        option.set("noslip_iterations", iterations.max(current));
    }

    /// Explicit contact pairs between every collision geom of the robot's finger links (those
    /// with their own material friction) and the geom `object`: condim 4 with the combined
    /// friction μ = (finger material + 0.3)/2 and torsional friction μ·`patch_radius` (PhysX's
    /// torsional patch friction, torque ≤ μ·r·N), with the default `solref`, `solimp` and
    /// margin. MuJoCo skips the dynamic contacts of body pairs that have explicit pairs, so
    /// these replace the fingers' condim-3 contacts with that object only (other objects keep
    /// them). Does nothing for a robot without such fingers.
    pub fn add_finger_pairs(&mut self, object: &str, patch_radius: f64) {
        let mut geoms = Vec::new();
        for (link, mu) in &self.fingers {
            if let Some(body) = find_body(&self.root, link) {
                for g in body.children.iter().filter(|c| c.name == "geom") {
                    let name = g.attrs.iter().find(|(k, _)| k == "name").map(|(_, v)| v);
                    if let Some(n) = name.filter(|n| n.starts_with(&format!("{link}_collision"))) {
                        geoms.push((n.clone(), (mu + DEFAULT_FRICTION) / 2.0));
                    }
                }
            }
        }
        let solref = stiff_solref(self.timestep);
        for (geom, mu) in geoms {
            let friction = [
                mu,
                mu,
                mu * patch_radius,
                TORSIONAL_ROLLING[1],
                TORSIONAL_ROLLING[1],
            ];
            self.section("contact").push(
                Element::new("pair")
                    .attr("geom1", geom)
                    .attr("geom2", object)
                    .attr("condim", 4)
                    .attr_nums("friction", &friction)
                    .attr_nums("solref", &solref)
                    .attr_nums("solimp", &CONTACT_SOLIMP)
                    .attr("margin", num(CONTACT_MARGIN)),
            );
        }
    }

    /// Finishes the document.
    pub fn finish(self) -> Mjcf {
        Mjcf {
            xml: self.root.to_xml(),
            assets: self.assets,
        }
    }

    /// The scene as [`Scene::finish`] writes it, and its physics model: the same document
    /// without the geoms that only draw (`contype` and `conaffinity` 0, named in no
    /// `<pair>`) and without the meshes, materials and textures only they used. Bodies,
    /// joints, cameras and sites, and so every id but the geoms', are the same in both.
    /// MuJoCo 2.2's broad phase visits every geom of a body, colliding or not, so the
    /// robots' visual meshes cost a tenth of a physics step (docs/speed.md).
    pub fn finish_with_physics(self) -> (Mjcf, Mjcf) {
        let mut physics = self.root.clone();
        let mut paired = Vec::new();
        collect_pair_geoms(&physics, &mut paired);
        strip_visual_geoms(&mut physics, &paired);
        // What the remaining geoms use: meshes and materials, then the materials' textures.
        let mut used = Vec::new();
        collect_geom_refs(&physics, &mut used);
        let mut files = Vec::new();
        if let Some(asset) = physics.children.iter_mut().find(|c| c.name == "asset") {
            asset.children.retain(|a| match a.name.as_str() {
                "mesh" | "material" => {
                    attr(a, "name").is_some_and(|n| used.contains(&n.to_string()))
                }
                _ => true,
            });
            let textures: Vec<String> = asset
                .children
                .iter()
                .filter(|a| a.name == "material")
                .filter_map(|a| attr(a, "texture").map(str::to_string))
                .collect();
            asset.children.retain(|a| {
                a.name != "texture"
                    || attr(a, "name").is_some_and(|n| textures.contains(&n.to_string()))
            });
            files.extend(
                asset
                    .children
                    .iter()
                    .filter_map(|a| attr(a, "file").map(str::to_string)),
            );
        }
        let physics = Mjcf {
            xml: physics.to_xml(),
            assets: self
                .assets
                .iter()
                .filter(|(name, _)| files.contains(name))
                .cloned()
                .collect(),
        };
        (self.finish(), physics)
    }
}

/// Attribute `k` of `e`.
fn attr<'a>(e: &'a Element, k: &str) -> Option<&'a str> {
    e.attrs
        .iter()
        .find(|(kk, _)| kk == k)
        .map(|(_, v)| v.as_str())
}

/// The geom names of every `<pair>` below `e`.
fn collect_pair_geoms(e: &Element, out: &mut Vec<String>) {
    if e.name == "pair" {
        out.extend(
            ["geom1", "geom2"]
                .iter()
                .filter_map(|k| attr(e, k).map(str::to_string)),
        );
    }
    for c in &e.children {
        collect_pair_geoms(c, out);
    }
}

/// Removes, below `e`, every geom that only draws: `contype` and `conaffinity` both "0" and
/// its name not in `paired`.
fn strip_visual_geoms(e: &mut Element, paired: &[String]) {
    e.children.retain(|c| {
        let drawn_only = c.name == "geom"
            && attr(c, "contype") == Some("0")
            && attr(c, "conaffinity") == Some("0")
            && !attr(c, "name").is_some_and(|n| paired.iter().any(|p| p == n));
        !drawn_only
    });
    for c in &mut e.children {
        strip_visual_geoms(c, paired);
    }
}

/// The mesh and material names the geoms below `e` use (the default class's too).
fn collect_geom_refs(e: &Element, out: &mut Vec<String>) {
    if e.name == "geom" {
        out.extend(
            ["mesh", "material"]
                .iter()
                .filter_map(|k| attr(e, k).map(str::to_string)),
        );
    }
    for c in &e.children {
        collect_geom_refs(c, out);
    }
}

/// The body element named `name` anywhere below `e`.
fn find_body<'a>(e: &'a Element, name: &str) -> Option<&'a Element> {
    if e.name == "body" && e.attrs.iter().any(|(k, v)| k == "name" && v == name) {
        return Some(e);
    }
    e.children.iter().find_map(|c| find_body(c, name))
}

/// Name of the k-th collision geom of a link.
pub fn collision_geom_name(link: &str, k: usize) -> String {
    format!("{link}_collision{k}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn control_dt_is_the_literal_period_of_control_freq() {
        // Derived from CONTROL_FREQ, bitwise the 0.05 every timestep was computed from.
        assert_eq!(super::CONTROL_DT.to_bits(), 0.05f64.to_bits());
    }
}
