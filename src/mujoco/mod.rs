//! The safe MuJoCo layer: the only module of mjskill that contains `unsafe` code.
//!
//! In the style of rusqlite over libsqlite3-sys: owned handles ([`Model`], [`Data`]) that free
//! their C memory on `Drop`, borrowed slice views of the C arrays sized from the model, and
//! `Result`s whose errors carry MuJoCo's own message text.
//!
//! MuJoCo keeps some process-wide globals (`mju_user_error`, `mju_user_warning`). [`init`]
//! installs handlers for them exactly once, before any model is loaded, so MuJoCo never calls
//! `exit()` or writes `MUJOCO_LOG.TXT` into the working directory. Instabilities are not
//! printed; they are counted in `mjData.warning` and surfaced through [`Data::warnings`].
#![allow(unsafe_code)]

pub mod filter;
pub(crate) mod limits;
pub mod render;
pub mod timer;

use std::ffi::{CStr, CString};
use std::os::raw::{c_char, c_int};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use mujoco_sys as sys;

/// Errors of the safe layer; every variant carries the text MuJoCo (or the check) produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MjError {
    /// The loaded C library is not MuJoCo 2.2.x.
    #[error("libmujoco reports version {found}, but mjskill needs MuJoCo 2.2.x (Debian's libmujoco-dev 2.2.2)")]
    Version {
        /// `mj_version()` of the loaded library (e.g. 222).
        found: i32,
    },
    /// MuJoCo's XML parser or model compiler rejected the model.
    #[error("MuJoCo could not load the model: {0}")]
    Load(String),
    /// A name, size or argument was invalid before MuJoCo was called.
    #[error("{0}")]
    Invalid(String),
}

/// Result type of the safe layer.
pub type Result<T> = std::result::Result<T, MjError>;

static INIT: OnceLock<std::result::Result<(), MjError>> = OnceLock::new();
static WARNINGS_SEEN: AtomicU64 = AtomicU64::new(0);

/// `mju_user_error` handler. MuJoCo's default prints, waits for Enter and calls `exit(1)`;
/// Rust cannot unwind through C, so this prints MuJoCo's message and aborts. Inputs are
/// validated before calling MuJoCo so that this cannot happen in normal use. (The XML
/// compiler installs its own handler while loading, so load errors arrive as text instead.)
unsafe extern "C" fn error_handler(msg: *const c_char) {
    // SAFETY: MuJoCo passes a NUL-terminated message string (or null).
    let text = if msg.is_null() {
        "(no message)".into()
    } else {
        unsafe { CStr::from_ptr(msg) }.to_string_lossy()
    };
    eprintln!("fatal MuJoCo error: {text}");
    std::process::abort();
}

/// `mju_user_warning` handler: counts instead of printing. The per-kind counters that callers
/// need live in `mjData.warning` ([`Data::warnings`]).
unsafe extern "C" fn warning_handler(_msg: *const c_char) {
    WARNINGS_SEEN.fetch_add(1, Ordering::Relaxed);
}

/// The version number the loaded library reports (`mj_version()`, 222 for 2.2.2).
pub fn version() -> i32 {
    // SAFETY: mj_version takes no arguments and only returns a constant.
    unsafe { sys::mj_version() }
}

/// The version string of the loaded library, e.g. "2.2.2".
pub fn version_string() -> String {
    // SAFETY: mj_versionString returns a pointer to a static NUL-terminated string.
    unsafe { CStr::from_ptr(sys::mj_versionString()) }
        .to_string_lossy()
        .into_owned()
}

/// Checks that the loaded library is MuJoCo 2.2.x and installs the error and warning handlers
/// and the contact filter ([`filter`]).
/// Idempotent and thread-safe; every constructor in this module calls it.
pub fn init() -> Result<()> {
    INIT.get_or_init(|| {
        let found = version();
        if !(220..230).contains(&found) {
            return Err(MjError::Version { found });
        }
        // SAFETY: the handlers are plain `extern "C"` functions with the signature MuJoCo
        // expects; this runs once, under the OnceLock, before any model is created here.
        unsafe {
            sys::mju_user_error = Some(error_handler);
            sys::mju_user_warning = Some(warning_handler);
        }
        filter::install();
        Ok(())
    })
    .clone()
}

/// Number of MuJoCo warnings raised in this process (all models), for diagnostics.
pub fn warnings_seen() -> u64 {
    WARNINGS_SEEN.load(Ordering::Relaxed)
}

/// MuJoCo object types used for name lookups (`mjtObj`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjType {
    /// A body.
    Body,
    /// A joint.
    Joint,
    /// A geom.
    Geom,
    /// A site.
    Site,
    /// A camera.
    Camera,
    /// An actuator.
    Actuator,
    /// An equality constraint.
    Equality,
    /// A keyframe.
    Key,
}

impl ObjType {
    fn raw(self) -> c_int {
        (match self {
            ObjType::Body => sys::mjtObj__mjOBJ_BODY,
            ObjType::Joint => sys::mjtObj__mjOBJ_JOINT,
            ObjType::Geom => sys::mjtObj__mjOBJ_GEOM,
            ObjType::Site => sys::mjtObj__mjOBJ_SITE,
            ObjType::Camera => sys::mjtObj__mjOBJ_CAMERA,
            ObjType::Actuator => sys::mjtObj__mjOBJ_ACTUATOR,
            ObjType::Equality => sys::mjtObj__mjOBJ_EQUALITY,
            ObjType::Key => sys::mjtObj__mjOBJ_KEY,
        }) as c_int
    }

    fn count(self, m: &sys::mjModel) -> c_int {
        match self {
            ObjType::Body => m.nbody,
            ObjType::Joint => m.njnt,
            ObjType::Geom => m.ngeom,
            ObjType::Site => m.nsite,
            ObjType::Camera => m.ncam,
            ObjType::Actuator => m.nu,
            ObjType::Equality => m.neq,
            ObjType::Key => m.nkey,
        }
    }
}

/// MuJoCo's `mjGEOM_BOX` (a value of [`Model::geom_type`]).
pub const GEOM_BOX: c_int = sys::mjtGeom__mjGEOM_BOX as c_int;
/// MuJoCo's `mjGEOM_SPHERE` (a value of [`Model::geom_type`]).
pub const GEOM_SPHERE: c_int = sys::mjtGeom__mjGEOM_SPHERE as c_int;

/// Joint types (`mjtJoint`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    /// Free joint: 7 qpos, 6 dofs.
    Free,
    /// Ball joint: 4 qpos, 3 dofs.
    Ball,
    /// Prismatic joint.
    Slide,
    /// Revolute joint.
    Hinge,
}

/// Instability warnings that MuJoCo counts in `mjData.warning` (`mjtWarning`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Warning {
    /// Bad inertia in a body.
    Inertia = 0,
    /// Too many contacts.
    ContactFull = 1,
    /// Too many constraints.
    ConstraintFull = 2,
    /// Too many visual geoms.
    VGeomFull = 3,
    /// NaN/inf or huge value in qpos (the simulation was reset).
    BadQpos = 4,
    /// NaN/inf or huge value in qvel (the simulation was reset).
    BadQvel = 5,
    /// NaN/inf or huge value in qacc (the simulation was reset): the model diverged.
    BadQacc = 6,
    /// NaN/inf in ctrl.
    BadCtrl = 7,
}

/// All warning kinds, in `mjtWarning` order.
pub const ALL_WARNINGS: [Warning; 8] = [
    Warning::Inertia,
    Warning::ContactFull,
    Warning::ConstraintFull,
    Warning::VGeomFull,
    Warning::BadQpos,
    Warning::BadQvel,
    Warning::BadQacc,
    Warning::BadCtrl,
];

/// Per-kind warning counters of one [`Data`], copied out of `mjData.warning`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Warnings {
    /// `counts[k]` = how often warning kind `k` ([`ALL_WARNINGS`] order) fired since the last clear.
    pub counts: [i32; 8],
}

impl Warnings {
    /// How often `w` fired.
    pub fn count(&self, w: Warning) -> i32 {
        self.counts[w as usize]
    }
    /// True if any of the "simulation diverged" warnings (bad qpos/qvel/qacc/ctrl) fired.
    pub fn diverged(&self) -> bool {
        [
            Warning::BadQpos,
            Warning::BadQvel,
            Warning::BadQacc,
            Warning::BadCtrl,
        ]
        .iter()
        .any(|w| self.count(*w) > 0)
    }
    /// The kinds that fired, for messages.
    pub fn fired(&self) -> Vec<Warning> {
        ALL_WARNINGS
            .iter()
            .copied()
            .filter(|w| self.count(*w) > 0)
            .collect()
    }
}

/// An owned, compiled MuJoCo model (`mjModel`). Freed on drop.
pub struct Model {
    ptr: *mut sys::mjModel,
}

// SAFETY: mjModel is a plain heap block owned by this handle; MuJoCo only reads it during
// simulation, and mutation goes through `&mut self`, so sharing `&Model` across threads is safe.
unsafe impl Send for Model {}
// SAFETY: see above — all `&self` methods only read.
unsafe impl Sync for Model {}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: ptr came from mj_loadXML, is non-null and is freed exactly once here.
        unsafe { sys::mj_deleteModel(self.ptr) }
    }
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Model(nq={}, nv={}, nu={}, nbody={}, ngeom={})",
            self.nq(),
            self.nv(),
            self.nu(),
            self.nbody(),
            self.ngeom()
        )
    }
}

/// A heap-allocated MuJoCo virtual file system (`mjVFS` is ~2 MB: too big for a thread stack).
struct Vfs(Box<sys::mjVFS>);

impl Vfs {
    fn new() -> Self {
        let mut b = Box::<sys::mjVFS>::new_uninit();
        // SAFETY: mj_defaultVFS initialises every field of the struct it is given.
        unsafe {
            sys::mj_defaultVFS(b.as_mut_ptr());
            Vfs(b.assume_init())
        }
    }

    fn add(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let cname = c_string(name)?;
        if name.len() >= 1000 {
            return Err(MjError::Invalid(format!(
                "asset file name too long for MuJoCo's VFS: {name}"
            )));
        }
        let len = c_int::try_from(bytes.len().max(1)).map_err(|_| {
            MjError::Invalid(format!("asset {name} is too large ({} bytes)", bytes.len()))
        })?;
        // SAFETY: self.0 is an initialised VFS; cname is NUL-terminated.
        let rc = unsafe { sys::mj_makeEmptyFileVFS(&mut *self.0, cname.as_ptr(), len) };
        match rc {
            0 => {}
            1 => {
                return Err(MjError::Invalid(format!(
                    "MuJoCo's VFS is full (2000 files); cannot add {name}"
                )))
            }
            2 => {
                return Err(MjError::Invalid(format!(
                    "duplicate asset file name {name}"
                )))
            }
            other => {
                return Err(MjError::Invalid(format!(
                    "mj_makeEmptyFileVFS({name}) failed with code {other}"
                )))
            }
        }
        // SAFETY: the file was just created, so findFile returns its valid index.
        let idx = unsafe { sys::mj_findFileVFS(&*self.0, cname.as_ptr()) };
        if idx < 0 {
            return Err(MjError::Invalid(format!(
                "asset {name} vanished from the VFS"
            )));
        }
        let dst = self.0.filedata[idx as usize] as *mut u8;
        // SAFETY: mj_makeEmptyFileVFS allocated `len >= bytes.len()` bytes at dst.
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), dst, bytes.len()) };
        Ok(())
    }
}

impl Drop for Vfs {
    fn drop(&mut self) {
        // SAFETY: the VFS was initialised by mj_defaultVFS; this frees the file buffers once.
        unsafe { sys::mj_deleteVFS(&mut *self.0) }
    }
}

fn c_string(s: &str) -> Result<CString> {
    CString::new(s).map_err(|_| MjError::Invalid(format!("string contains a NUL byte: {s:?}")))
}

/// Builds a slice view of a C array owned by a model or data.
macro_rules! view {
    ($ptr:expr, $len:expr) => {{
        let p = $ptr;
        let n = $len as usize;
        if n == 0 || p.is_null() {
            &[]
        } else {
            // SAFETY: MuJoCo allocated `n` elements at `p` for the lifetime of the owning
            // handle, which the returned borrow cannot outlive.
            unsafe { std::slice::from_raw_parts(p, n) }
        }
    }};
}

macro_rules! view_mut {
    ($ptr:expr, $len:expr) => {{
        let p = $ptr;
        let n = $len as usize;
        if n == 0 || p.is_null() {
            &mut []
        } else {
            // SAFETY: as `view!`, and the `&mut self` receiver makes the borrow exclusive.
            unsafe { std::slice::from_raw_parts_mut(p, n) }
        }
    }};
}

/// Read-only model arrays exposed as slices: `name(&self) -> &[T]`.
macro_rules! model_arrays {
    ($($(#[$doc:meta])* $name:ident : $ty:ty = $len:expr;)*) => {
        impl Model {
            $(
                $(#[$doc])*
                pub fn $name(&self) -> &[$ty] {
                    let m = self.raw();
                    view!(m.$name, $len(m))
                }
            )*
        }
    };
}

model_arrays! {
    /// Parent body id of every body.
    body_parentid: c_int = |m: &sys::mjModel| m.nbody;
    /// Mocap index of every body (-1 for non-mocap bodies).
    body_mocapid: c_int = |m: &sys::mjModel| m.nbody;
    /// Mass of every body.
    body_mass: f64 = |m: &sys::mjModel| m.nbody;
    /// Diagonal inertia (principal frame) of every body, 3 per body.
    body_inertia: f64 = |m: &sys::mjModel| m.nbody * 3;
    /// Position of the inertial frame relative to the body frame, 3 per body.
    body_ipos: f64 = |m: &sys::mjModel| m.nbody * 3;
    /// Orientation of the inertial frame relative to the body frame, 4 per body.
    body_iquat: f64 = |m: &sys::mjModel| m.nbody * 4;
    /// First joint of every body (-1 for a body without joints).
    body_jntadr: c_int = |m: &sys::mjModel| m.nbody;
    /// Number of dofs of every body.
    body_dofnum: c_int = |m: &sys::mjModel| m.nbody;
    /// Joint type of every joint (`mjtJoint`).
    jnt_type: c_int = |m: &sys::mjModel| m.njnt;
    /// qpos address of every joint.
    jnt_qposadr: c_int = |m: &sys::mjModel| m.njnt;
    /// dof address of every joint.
    jnt_dofadr: c_int = |m: &sys::mjModel| m.njnt;
    /// Body of every joint.
    jnt_bodyid: c_int = |m: &sys::mjModel| m.njnt;
    /// Whether the joint is limited.
    jnt_limited: u8 = |m: &sys::mjModel| m.njnt;
    /// Joint limits, 2 per joint.
    jnt_range: f64 = |m: &sys::mjModel| m.njnt * 2;
    /// Armature of every dof.
    dof_armature: f64 = |m: &sys::mjModel| m.nv;
    /// Damping of every dof.
    dof_damping: f64 = |m: &sys::mjModel| m.nv;
    /// Joint of every dof.
    dof_jntid: c_int = |m: &sys::mjModel| m.nv;
    /// Body of every dof.
    dof_bodyid: c_int = |m: &sys::mjModel| m.nv;
    /// Parent dof of every dof (-1 at a tree's root).
    dof_parentid: c_int = |m: &sys::mjModel| m.nv;
    /// Number of consecutive simple dofs (diagonal inertia) from every dof on.
    dof_simplenum: c_int = |m: &sys::mjModel| m.nv;
    /// Geom type of every geom (`mjtGeom`).
    geom_type: c_int = |m: &sys::mjModel| m.ngeom;
    /// Body of every geom.
    geom_bodyid: c_int = |m: &sys::mjModel| m.ngeom;
    /// contype bits of every geom.
    geom_contype: c_int = |m: &sys::mjModel| m.ngeom;
    /// conaffinity bits of every geom.
    geom_conaffinity: c_int = |m: &sys::mjModel| m.ngeom;
    /// Visual group of every geom.
    geom_group: c_int = |m: &sys::mjModel| m.ngeom;
    /// Radius of every geom's bounding sphere (0 for planes).
    geom_rbound: f64 = |m: &sys::mjModel| m.ngeom;
    /// Geom collision gaps (m): contacts beyond `margin − gap` are reported but inactive.
    geom_gap: f64 = |m: &sys::mjModel| m.ngeom;
    /// Geom sizes, 3 per geom (MuJoCo's type-dependent meaning).
    geom_size: f64 = |m: &sys::mjModel| m.ngeom * 3;
    /// Geom colours, 4 per geom.
    geom_rgba: f32 = |m: &sys::mjModel| m.ngeom * 4;
    /// Geom friction, 3 per geom.
    geom_friction: f64 = |m: &sys::mjModel| m.ngeom * 3;
    /// Geom positions in their body frame, 3 per geom.
    geom_pos: f64 = |m: &sys::mjModel| m.ngeom * 3;
    /// Geom orientations in their body frame, 4 per geom.
    geom_quat: f64 = |m: &sys::mjModel| m.ngeom * 4;
    /// Mesh id of every geom (-1 unless a mesh).
    geom_dataid: c_int = |m: &sys::mjModel| m.ngeom;
    /// Body of every site.
    site_bodyid: c_int = |m: &sys::mjModel| m.nsite;
    /// Site positions in their body frame, 3 per site.
    site_pos: f64 = |m: &sys::mjModel| m.nsite * 3;
    /// Transmission target of every actuator, 2 per actuator (joint id, unused).
    actuator_trnid: c_int = |m: &sys::mjModel| m.nu * 2;
    /// Actuator gain parameters, 10 per actuator.
    actuator_gainprm: f64 = |m: &sys::mjModel| m.nu * 10;
    /// Actuator bias parameters, 10 per actuator.
    actuator_biasprm: f64 = |m: &sys::mjModel| m.nu * 10;
    /// Actuator force ranges, 2 per actuator.
    actuator_forcerange: f64 = |m: &sys::mjModel| m.nu * 2;
    /// Equality constraint types.
    eq_type: c_int = |m: &sys::mjModel| m.neq;
    /// Camera positions, 3 per camera.
    cam_pos: f64 = |m: &sys::mjModel| m.ncam * 3;
    /// Camera orientations, 4 per camera.
    cam_quat: f64 = |m: &sys::mjModel| m.ncam * 4;
    /// Camera vertical field of view in degrees.
    cam_fovy: f64 = |m: &sys::mjModel| m.ncam;
    /// Body of every camera.
    cam_bodyid: c_int = |m: &sys::mjModel| m.ncam;
}

impl Model {
    /// Compiles an MJCF document held in memory. `assets` are (file name, bytes) pairs placed
    /// in MuJoCo's virtual file system under the names the XML refers to (meshes).
    /// Errors carry MuJoCo's parser/compiler message.
    pub fn from_xml_string(xml: &str, assets: &[(&str, &[u8])]) -> Result<Model> {
        init()?;
        const MAIN: &str = "__mjskill_model__.xml";
        let mut vfs = Vfs::new();
        vfs.add(MAIN, xml.as_bytes())?;
        for (name, bytes) in assets {
            vfs.add(name, bytes)?;
        }
        let main = c_string(MAIN)?;
        let mut err = vec![0 as c_char; 2048];
        // SAFETY: main is NUL-terminated, the VFS is initialised and outlives the call, and
        // err has the length we pass.
        let ptr = unsafe {
            sys::mj_loadXML(main.as_ptr(), &*vfs.0, err.as_mut_ptr(), err.len() as c_int)
        };
        if ptr.is_null() {
            // SAFETY: MuJoCo writes a NUL-terminated message into err (zero-initialised).
            let msg = unsafe { CStr::from_ptr(err.as_ptr()) }
                .to_string_lossy()
                .trim()
                .to_string();
            return Err(MjError::Load(if msg.is_empty() {
                "unknown error".into()
            } else {
                msg
            }));
        }
        Ok(Model { ptr })
    }

    fn raw(&self) -> &sys::mjModel {
        // SAFETY: ptr is non-null and valid for the lifetime of self.
        unsafe { &*self.ptr }
    }

    /// Bytes of the model's own arrays (`mjModel.nbuffer`: meshes and textures included).
    pub fn memory_bytes(&self) -> usize {
        self.raw().nbuffer as usize
    }

    /// Size of the stack every [`Data`] of this model gets, in `f64`s (`mjModel.nstack`).
    pub fn stack_size(&self) -> usize {
        self.raw().nstack as usize
    }

    /// The stack MuJoCo 2.2 can need for this model, in `f64`s: twice the sum of every
    /// stack allocation of the functions mjskill calls (`mj_step`, `mj_forward` and its
    /// stages, Jacobians, `mj_solveM`, `mj_setConst`), counted as if all were live at once.
    /// The largest are the constraint projection (`4·njmax·nv` with the sparse index arrays),
    /// the Newton solver (`3·nv²` plus `8·njmax`), `mj_fullM`-style dense matrices (`3·nv²`)
    /// and the broadphase's body pairs (`nbody²/2`). MuJoCo's compiler instead reserves
    /// `5·(njmax + neq + nv)²` (4 MB of a 4.7 MB env at `njmax` 300), since no stack use of
    /// 2.2 is quadratic in `njmax`.
    pub fn stack_bound(&self) -> usize {
        let m = self.raw();
        let n = |x: std::os::raw::c_int| x.max(0) as usize;
        let (nv, nefc, nbody) = (n(m.nv), n(m.njmax), n(m.nbody));
        let other = n(m.nq) + n(m.na) + n(m.nu) + n(m.ncam) + n(m.nlight) + n(m.neq);
        let sum = 4 * nefc * nv
            + 10 * nefc
            + 6 * nv * nv
            + nbody * nbody
            + 100 * nv
            + 30 * nbody
            + 10 * other
            + 1000;
        2 * sum
    }

    /// Lowers the stack every later [`Data`] of this model gets to [`Model::stack_bound`]
    /// when that is smaller than what the compiler chose (never raises it). Simulation is
    /// unchanged: the stack only holds temporaries, and a stack too small would abort
    /// (`mj_stackAlloc`'s "Stack overflow"), which the bound rules out.
    pub fn shrink_stack(&mut self) {
        let bound = self.stack_bound();
        if bound < self.stack_size() {
            // SAFETY: ptr is valid and exclusively borrowed; nstack is a plain size that
            // mj_makeData reads when allocating a stack (no Data of this model exists yet that
            // could depend on it: Data holds an Arc<Model>, and this takes &mut self).
            unsafe { (*self.ptr).nstack = bound as std::os::raw::c_int };
        }
    }

    /// Number of generalised coordinates.
    pub fn nq(&self) -> usize {
        self.raw().nq as usize
    }
    /// Number of degrees of freedom.
    pub fn nv(&self) -> usize {
        self.raw().nv as usize
    }
    /// Number of actuators.
    pub fn nu(&self) -> usize {
        self.raw().nu as usize
    }
    /// Number of activation states.
    pub fn na(&self) -> usize {
        self.raw().na as usize
    }
    /// Number of bodies (including the world body 0).
    pub fn nbody(&self) -> usize {
        self.raw().nbody as usize
    }
    /// Number of joints.
    pub fn njnt(&self) -> usize {
        self.raw().njnt as usize
    }
    /// Number of geoms.
    pub fn ngeom(&self) -> usize {
        self.raw().ngeom as usize
    }
    /// Number of sites.
    pub fn nsite(&self) -> usize {
        self.raw().nsite as usize
    }
    /// Number of mocap bodies.
    pub fn nmocap(&self) -> usize {
        self.raw().nmocap as usize
    }
    /// Number of cameras.
    pub fn ncam(&self) -> usize {
        self.raw().ncam as usize
    }
    /// Number of equality constraints.
    pub fn neq(&self) -> usize {
        self.raw().neq as usize
    }
    /// Simulation timestep in seconds.
    pub fn timestep(&self) -> f64 {
        self.raw().opt.timestep
    }
    /// Gravity vector.
    pub fn gravity(&self) -> [f64; 3] {
        self.raw().opt.gravity
    }
    /// Integrator (`mjtIntegrator`: 0 Euler, 1 RK4, 2 implicit).
    pub fn integrator(&self) -> i32 {
        self.raw().opt.integrator
    }
    /// Iterations of the no-slip pass after each constraint solve (`opt.noslip_iterations`).
    pub fn noslip_iterations(&self) -> usize {
        self.raw().opt.noslip_iterations as usize
    }
    /// Offscreen buffer size from `<visual><global offwidth offheight>`.
    pub fn offscreen_size(&self) -> (usize, usize) {
        let g = &self.raw().vis.global;
        (g.offwidth as usize, g.offheight as usize)
    }

    /// Looks up the id of a named object; `None` if no object of that type has this name.
    pub fn id(&self, ty: ObjType, name: &str) -> Option<usize> {
        let c = CString::new(name).ok()?;
        // SAFETY: model pointer valid, c NUL-terminated.
        let id = unsafe { sys::mj_name2id(self.ptr, ty.raw(), c.as_ptr()) };
        (id >= 0).then_some(id as usize)
    }

    /// Like [`Model::id`] but an error naming the missing object.
    pub fn require_id(&self, ty: ObjType, name: &str) -> Result<usize> {
        self.id(ty, name)
            .ok_or_else(|| MjError::Invalid(format!("the model has no {ty:?} named {name:?}")))
    }

    /// The name of object `id` of type `ty` (empty if unnamed or out of range).
    pub fn name(&self, ty: ObjType, id: usize) -> String {
        if id >= ty.count(self.raw()) as usize {
            return String::new();
        }
        // SAFETY: id is in range, so mj_id2name returns null or a pointer into m.names.
        let p = unsafe { sys::mj_id2name(self.ptr, ty.raw(), id as c_int) };
        if p.is_null() {
            String::new()
        } else {
            // SAFETY: names are NUL-terminated inside the model's name buffer.
            unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    }

    /// Type of joint `j`.
    pub fn joint_type(&self, j: usize) -> JointType {
        match self.jnt_type()[j] as u32 {
            sys::mjtJoint__mjJNT_FREE => JointType::Free,
            sys::mjtJoint__mjJNT_BALL => JointType::Ball,
            sys::mjtJoint__mjJNT_SLIDE => JointType::Slide,
            _ => JointType::Hinge,
        }
    }
}

// After the array macros above, which it uses (macros are scoped textually).
mod data;
pub use data::{Contact, Data};
mod edit;
mod ids;
pub use ids::{ActuatorId, BodyId, CameraId, GeomId, JointId, MocapId, Pose};

impl Model {
    /// Address of every dof's row of the inertia in MuJoCo's sparse layout (`dof_Madr`: the
    /// row's diagonal in `qM` and `qLD`, followed by its ancestors' entries).
    pub fn dof_madr(&self) -> &[c_int] {
        let m = self.raw();
        view!(m.dof_Madr, m.nv)
    }

    /// Size of the sparse inertia (`nM`: the entries of `qM` and `qLD`).
    pub fn n_m(&self) -> usize {
        self.raw().nM as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOX_ON_PLANE: &str = r#"<mujoco>
      <option timestep="0.002"/>
      <worldbody>
        <geom name="floor" type="plane" size="1 1 0.1"/>
        <body name="box" pos="0 0 0.1">
          <freejoint/>
          <geom name="b" type="box" size="0.05 0.05 0.05" mass="1"/>
          <site name="s" pos="0 0 0.05"/>
        </body>
      </worldbody>
    </mujoco>"#;

    #[test]
    fn version_is_2_2() {
        init().unwrap();
        assert!((220..230).contains(&version()), "version {}", version());
        assert!(version_string().starts_with("2.2"));
    }

    #[test]
    fn bad_xml_returns_mujoco_message() {
        let err = Model::from_xml_string(
            "<mujoco><worldbody><geom type='sphere' size='-1'/></worldbod></mujoco>",
            &[],
        )
        .unwrap_err();
        match err {
            MjError::Load(msg) => assert!(!msg.is_empty(), "empty message"),
            other => panic!("wrong error {other:?}"),
        }
        let err = Model::from_xml_string(
            "<mujoco><worldbody><body><joint type='bogus'/></body></worldbody></mujoco>",
            &[],
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("bogus") || err.to_string().contains("invalid"),
            "{err}"
        );
    }

    #[test]
    fn box_rests_on_floor_with_upward_contact_force() {
        let m = Arc::new(Model::from_xml_string(BOX_ON_PLANE, &[]).unwrap());
        let mut d = Data::new(m.clone()).unwrap();
        for _ in 0..1000 {
            d.step();
        }
        let b = m.require_id(ObjType::Body, "box").unwrap();
        assert!(
            (d.xpos()[3 * b + 2] - 0.05).abs() < 2e-3,
            "z = {}",
            d.xpos()[3 * b + 2]
        );
        assert!(d.ncon() >= 1);
        // Sum of the world-frame force on the box from all contacts: must be +m g along z.
        let floor = m.require_id(ObjType::Geom, "floor").unwrap();
        let mut fz = 0.0;
        for i in 0..d.ncon() {
            let c = d.contact(i);
            let f = d.contact_force(i);
            // world force on geom2 = frame^T * f[0..3]
            let mut w = [0.0; 3];
            for (r, fr) in f.iter().enumerate().take(3) {
                for (k, wk) in w.iter_mut().enumerate() {
                    *wk += c.frame[3 * r + k] * fr;
                }
            }
            let sign = if c.geom2 == floor { -1.0 } else { 1.0 };
            fz += sign * w[2];
        }
        assert!((fz - 9.81).abs() < 0.2, "fz = {fz}");
        assert!(!d.warnings().diverged());
    }

    #[test]
    fn a_geom_gap_reports_contacts_before_they_touch() {
        const SPHERE_ABOVE_PLANE: &str = r#"<mujoco>
          <worldbody>
            <geom name="floor" type="plane" size="1 1 0.1"/>
            <body pos="0 0 0.055">
              <freejoint/>
              <geom name="ball" type="sphere" size="0.05" mass="1"/>
            </body>
          </worldbody>
        </mujoco>"#;
        let mut m = Model::from_xml_string(SPHERE_ABOVE_PLANE, &[]).unwrap();
        let ball = m.require_geom("ball").unwrap();
        let mut plain = Data::new(Arc::new(m.clone())).unwrap();
        plain.forward();
        assert_eq!(plain.ncon(), 0, "5 mm apart, no margin: no contact");
        for (margin, gap) in [(-0.01, 0.0), (0.01, 0.02), (f64::NAN, 0.0)] {
            let e = m
                .set_geom_margin(ball, margin, gap)
                .unwrap_err()
                .to_string();
            assert!(e.contains("margin") && e.contains("gap"), "{e}");
        }
        assert!(m
            .set_geom_margin(GeomId::from_index(99), 0.01, 0.01)
            .is_err());
        m.set_geom_margin(ball, 0.01, 0.01).unwrap();
        let mut d = Data::new(Arc::new(m)).unwrap();
        d.forward();
        assert_eq!(d.ncon(), 1);
        let c = d.contact(0);
        assert!(c.in_gap, "{:?}", c.dist);
        assert!((c.dist - 0.005).abs() < 1e-9, "dist {}", c.dist);
    }

    #[test]
    fn state_roundtrip_is_bitwise() {
        let m = Arc::new(Model::from_xml_string(BOX_ON_PLANE, &[]).unwrap());
        let mut d = Data::new(m).unwrap();
        d.qvel_mut()[0] = 0.3;
        d.qvel_mut()[5] = 2.0;
        for _ in 0..50 {
            d.step();
        }
        let mut s = Vec::new();
        d.get_state(&mut s);
        assert_eq!(s.len(), d.state_len());
        let mut a = d.clone();
        for _ in 0..100 {
            a.step();
        }
        d.step();
        d.set_state(&s).unwrap();
        for _ in 0..100 {
            d.step();
        }
        assert_eq!(a.qpos(), d.qpos());
        assert_eq!(a.qvel(), d.qvel());
        assert!(d.set_state(&s[1..]).is_err());
    }

    #[test]
    fn names_and_jacobian() {
        let m = Arc::new(Model::from_xml_string(BOX_ON_PLANE, &[]).unwrap());
        let mut d = Data::new(m.clone()).unwrap();
        d.forward();
        let s = m.require_id(ObjType::Site, "s").unwrap();
        assert_eq!(m.name(ObjType::Site, s), "s");
        assert!(m.id(ObjType::Body, "nope").is_none());
        assert!(m
            .require_id(ObjType::Body, "nope")
            .unwrap_err()
            .to_string()
            .contains("nope"));
        let nv = m.nv();
        let (mut jp, mut jr) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
        d.jac_site(s, &mut jp, &mut jr);
        // free joint: translational dofs map one-to-one.
        assert_eq!(jp[0], 1.0);
        assert_eq!(jp[nv + 1], 1.0);
        assert_eq!(jp[2 * nv + 2], 1.0);
    }

    #[test]
    fn mesh_asset_through_vfs() {
        // A tetrahedron as a binary STL in memory.
        let tris: [[[f32; 3]; 3]; 4] = [
            [[0., 0., 0.], [0.1, 0., 0.], [0., 0.1, 0.]],
            [[0., 0., 0.], [0., 0., 0.1], [0.1, 0., 0.]],
            [[0., 0., 0.], [0., 0.1, 0.], [0., 0., 0.1]],
            [[0.1, 0., 0.], [0., 0., 0.1], [0., 0.1, 0.]],
        ];
        let mut stl = vec![0u8; 80];
        stl.extend_from_slice(&(tris.len() as u32).to_le_bytes());
        for t in tris {
            stl.extend_from_slice(&[0u8; 12]);
            for v in t {
                for c in v {
                    stl.extend_from_slice(&c.to_le_bytes());
                }
            }
            stl.extend_from_slice(&[0u8; 2]);
        }
        let xml = r#"<mujoco><asset><mesh name="t" file="tet.stl"/></asset>
          <worldbody><body><freejoint/><geom type="mesh" mesh="t"/></body></worldbody></mujoco>"#;
        let m = Model::from_xml_string(xml, &[("tet.stl", &stl)]).unwrap();
        assert_eq!(m.ngeom(), 1);
        assert!(m.body_mass()[1] > 0.0);
        let err = Model::from_xml_string(xml, &[]).unwrap_err();
        assert!(err.to_string().contains("tet.stl"), "{err}");
    }
}
