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

pub mod render;

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

/// Checks that the loaded library is MuJoCo 2.2.x and installs the error and warning handlers.
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
    /// Body of every dof.
    dof_bodyid: c_int = |m: &sys::mjModel| m.nv;
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

/// One contact of the current state, copied out of `mjData.contact`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// First geom. The contact normal points from geom1 to geom2.
    pub geom1: usize,
    /// Second geom.
    pub geom2: usize,
    /// Signed distance (negative = penetration).
    pub dist: f64,
    /// Contact point in world coordinates.
    pub pos: [f64; 3],
    /// Contact frame, rows: normal, tangent1, tangent2 (world coordinates).
    pub frame: [f64; 9],
    /// Whether the contact was excluded from the constraint solver (gap).
    pub excluded: bool,
}

/// Owned simulation state (`mjData`) of one [`Model`]; keeps the model alive. Freed on drop.
pub struct Data {
    model: Arc<Model>,
    ptr: *mut sys::mjData,
    /// Scratch copy of qacc_warmstart, so that [`Data::forward`] leaves the future unchanged.
    warmstart: Vec<f64>,
}

// SAFETY: mjData is owned exclusively by this handle and only touched through it; the shared
// model is Sync. Moving it to another thread is therefore safe.
unsafe impl Send for Data {}

impl Drop for Data {
    fn drop(&mut self) {
        // SAFETY: ptr came from mj_makeData and is freed exactly once.
        unsafe { sys::mj_deleteData(self.ptr) }
    }
}

impl std::fmt::Debug for Data {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Data(time={}, {:?})", self.time(), self.model)
    }
}

impl Clone for Data {
    fn clone(&self) -> Self {
        // SAFETY: both pointers are valid; mj_makeData allocates a matching block and
        // mj_copyData copies every array of `self` into it.
        let ptr = unsafe {
            let dst = sys::mj_makeData(self.model.ptr);
            assert!(!dst.is_null(), "MuJoCo could not allocate mjData");
            sys::mj_copyData(dst, self.model.ptr, self.ptr)
        };
        Data {
            model: self.model.clone(),
            ptr,
            warmstart: self.warmstart.clone(),
        }
    }
}

/// Read-only data arrays: `name(&self) -> &[f64]`.
macro_rules! data_arrays {
    ($($(#[$doc:meta])* $name:ident = $len:expr;)*) => {
        impl Data {
            $(
                $(#[$doc])*
                pub fn $name(&self) -> &[f64] {
                    let m = self.model.raw();
                    view!(self.raw().$name, $len(m))
                }
            )*
        }
    };
}

/// Mutable data arrays: `name_mut(&mut self) -> &mut [f64]`.
macro_rules! data_arrays_mut {
    ($($(#[$doc:meta])* $name:ident, $field:ident = $len:expr;)*) => {
        impl Data {
            $(
                $(#[$doc])*
                pub fn $name(&mut self) -> &mut [f64] {
                    let n = $len(self.model.raw());
                    let p = self.raw().$field;
                    view_mut!(p, n)
                }
            )*
        }
    };
}

data_arrays! {
    /// Generalised positions.
    qpos = |m: &sys::mjModel| m.nq;
    /// Generalised velocities.
    qvel = |m: &sys::mjModel| m.nv;
    /// Generalised accelerations of the last step.
    qacc = |m: &sys::mjModel| m.nv;
    /// Warm start of the constraint solver (part of the state for exact replay).
    qacc_warmstart = |m: &sys::mjModel| m.nv;
    /// Actuator activations.
    act = |m: &sys::mjModel| m.na;
    /// Controls.
    ctrl = |m: &sys::mjModel| m.nu;
    /// Applied generalised forces.
    qfrc_applied = |m: &sys::mjModel| m.nv;
    /// Applied Cartesian forces at body centres of mass, 6 per body (force, torque).
    xfrc_applied = |m: &sys::mjModel| m.nbody * 6;
    /// Mocap body positions, 3 per mocap body.
    mocap_pos = |m: &sys::mjModel| m.nmocap * 3;
    /// Mocap body orientations (wxyz), 4 per mocap body.
    mocap_quat = |m: &sys::mjModel| m.nmocap * 4;
    /// Body frame positions, 3 per body.
    xpos = |m: &sys::mjModel| m.nbody * 3;
    /// Body frame orientations (wxyz), 4 per body.
    xquat = |m: &sys::mjModel| m.nbody * 4;
    /// Body frame orientations as row-major 3x3 matrices, 9 per body.
    xmat = |m: &sys::mjModel| m.nbody * 9;
    /// Body centre-of-mass positions, 3 per body.
    xipos = |m: &sys::mjModel| m.nbody * 3;
    /// Geom positions, 3 per geom.
    geom_xpos = |m: &sys::mjModel| m.ngeom * 3;
    /// Geom orientations (row-major 3x3), 9 per geom.
    geom_xmat = |m: &sys::mjModel| m.ngeom * 9;
    /// Site positions, 3 per site.
    site_xpos = |m: &sys::mjModel| m.nsite * 3;
    /// Site orientations (row-major 3x3), 9 per site.
    site_xmat = |m: &sys::mjModel| m.nsite * 9;
    /// Camera positions, 3 per camera.
    cam_xpos = |m: &sys::mjModel| m.ncam * 3;
    /// Camera orientations (row-major 3x3; columns: right, up, backward), 9 per camera.
    cam_xmat = |m: &sys::mjModel| m.ncam * 9;
    /// Bias forces (Coriolis, centrifugal, gravity).
    qfrc_bias = |m: &sys::mjModel| m.nv;
    /// Unconstrained accelerations (`mj_fwdAcceleration`).
    qacc_smooth = |m: &sys::mjModel| m.nv;
    /// Actuator forces of the last step.
    actuator_force = |m: &sys::mjModel| m.nu;
}

data_arrays_mut! {
    /// Mutable generalised positions.
    qpos_mut, qpos = |m: &sys::mjModel| m.nq;
    /// Mutable generalised velocities.
    qvel_mut, qvel = |m: &sys::mjModel| m.nv;
    /// Mutable solver warm start.
    qacc_warmstart_mut, qacc_warmstart = |m: &sys::mjModel| m.nv;
    /// Mutable activations.
    act_mut, act = |m: &sys::mjModel| m.na;
    /// Mutable controls.
    ctrl_mut, ctrl = |m: &sys::mjModel| m.nu;
    /// Mutable applied generalised forces.
    qfrc_applied_mut, qfrc_applied = |m: &sys::mjModel| m.nv;
    /// Mutable applied Cartesian forces (6 per body, at the centre of mass).
    xfrc_applied_mut, xfrc_applied = |m: &sys::mjModel| m.nbody * 6;
    /// Mutable mocap positions.
    mocap_pos_mut, mocap_pos = |m: &sys::mjModel| m.nmocap * 3;
    /// Mutable mocap orientations (wxyz).
    mocap_quat_mut, mocap_quat = |m: &sys::mjModel| m.nmocap * 4;
}

impl Data {
    /// Allocates simulation data for `model`, initialised to the model's reference state.
    pub fn new(model: Arc<Model>) -> Result<Data> {
        init()?;
        // SAFETY: model pointer valid; mj_makeData returns null only on allocation failure.
        let ptr = unsafe { sys::mj_makeData(model.ptr) };
        if ptr.is_null() {
            return Err(MjError::Invalid("MuJoCo could not allocate mjData".into()));
        }
        let warmstart = vec![0.0; model.nv()];
        Ok(Data {
            model,
            ptr,
            warmstart,
        })
    }

    fn raw(&self) -> &sys::mjData {
        // SAFETY: ptr is non-null and valid for the lifetime of self.
        unsafe { &*self.ptr }
    }

    /// The model this data belongs to.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// Simulation time in seconds.
    pub fn time(&self) -> f64 {
        self.raw().time
    }
    /// Sets the simulation time.
    pub fn set_time(&mut self, t: f64) {
        // SAFETY: ptr valid, exclusive through &mut self.
        unsafe { (*self.ptr).time = t }
    }

    /// One full physics step (`mj_step`).
    pub fn step(&mut self) {
        // SAFETY: model and data pointers are valid and belong together.
        unsafe { sys::mj_step(self.model.ptr, self.ptr) }
    }
    /// Actuation and unconstrained acceleration (`mj_fwdActuation`, `mj_fwdAcceleration`)
    /// for the current controls: fills `qacc_smooth`. Call after [`Data::step1`].
    pub fn smooth_acceleration(&mut self) {
        // SAFETY: as step.
        unsafe {
            sys::mj_fwdActuation(self.model.ptr, self.ptr);
            sys::mj_fwdAcceleration(self.model.ptr, self.ptr);
        }
    }
    /// First half of a step (`mj_step1`: positions, velocities, forces up to the controls).
    pub fn step1(&mut self) {
        // SAFETY: as step.
        unsafe { sys::mj_step1(self.model.ptr, self.ptr) }
    }
    /// Second half of a step (`mj_step2`: actuation, acceleration, integration).
    pub fn step2(&mut self) {
        // SAFETY: as step.
        unsafe { sys::mj_step2(self.model.ptr, self.ptr) }
    }
    /// Recomputes every derived quantity without integrating (`mj_forward`).
    ///
    /// MuJoCo 2.2's `mj_forward` also overwrites the solver warm start (`qacc_warmstart`),
    /// which would make the next [`Data::step`] differ in the last bits from a trajectory that
    /// never called it. This keeps the warm start, so calling `forward` never changes the future.
    pub fn forward(&mut self) {
        let mut ws = std::mem::take(&mut self.warmstart);
        ws.copy_from_slice(self.qacc_warmstart());
        // SAFETY: as step.
        unsafe { sys::mj_forward(self.model.ptr, self.ptr) }
        self.qacc_warmstart_mut().copy_from_slice(&ws);
        self.warmstart = ws;
    }
    /// Runs only the kinematics (positions of bodies, geoms, sites) (`mj_kinematics`).
    pub fn kinematics(&mut self) {
        // SAFETY: as step.
        unsafe { sys::mj_kinematics(self.model.ptr, self.ptr) }
    }
    /// Memory MuJoCo allocated for this `mjData`: (main buffer bytes, stack bytes).
    pub fn memory_bytes(&self) -> (usize, usize) {
        let d = self.raw();
        (
            d.nbuffer as usize,
            d.nstack as usize * std::mem::size_of::<f64>(),
        )
    }
    /// Brings poses and velocities derived from qpos/qvel up to date after `step` (which
    /// leaves them at the start of the step): `mj_kinematics`, `mj_comPos`, `mj_camlight`
    /// (camera and light poses, for cameras mounted on moving bodies), `mj_comVel`.
    /// Touches nothing that influences the next step.
    pub fn update_kinematics(&mut self) {
        // SAFETY: as step.
        unsafe {
            sys::mj_kinematics(self.model.ptr, self.ptr);
            sys::mj_comPos(self.model.ptr, self.ptr);
            sys::mj_camlight(self.model.ptr, self.ptr);
            sys::mj_comVel(self.model.ptr, self.ptr);
        }
    }
    /// Resets to the model's reference state (`mj_resetData`); clears applied forces too.
    pub fn reset(&mut self) {
        // SAFETY: as step.
        unsafe { sys::mj_resetData(self.model.ptr, self.ptr) }
    }

    /// Warning counters since the last [`Data::clear_warnings`] (or reset).
    pub fn warnings(&self) -> Warnings {
        let mut w = Warnings::default();
        for (k, s) in self.raw().warning.iter().enumerate() {
            w.counts[k] = s.number;
        }
        w
    }
    /// Zeroes the warning counters.
    pub fn clear_warnings(&mut self) {
        // SAFETY: ptr valid, exclusive through &mut self; warning is a fixed-size array.
        unsafe {
            for s in (*self.ptr).warning.iter_mut() {
                s.number = 0;
                s.lastinfo = 0;
            }
        }
    }

    /// Number of equality-constraint rows in the current constraint set (`mjData.ne`).
    pub fn ne(&self) -> usize {
        self.raw().ne as usize
    }

    /// The Jacobian rows of the equality constraints (`ne` × nv, row-major), computed by the
    /// last [`Data::step1`] / [`Data::forward`]. The model must use dense Jacobians
    /// (`<option jacobian="dense">`, which mjskill's scenes set); `None` otherwise.
    pub fn equality_jacobian(&self) -> Option<&[f64]> {
        // SAFETY: model pointer valid for the lifetime of self.
        let sparse = unsafe { sys::mj_isSparse(self.model.ptr) } != 0;
        if sparse {
            return None;
        }
        let nv = self.model.nv();
        let d = self.raw();
        Some(view!(d.efc_J, d.ne as usize * nv))
    }

    /// Regularisers `R` of the first `n` constraint rows (`efc_R`: the compliance MuJoCo's
    /// soft constraints add to `J M⁻¹ Jᵀ`), computed by the last [`Data::step1`].
    pub fn efc_r(&self, n: usize) -> &[f64] {
        let d = self.raw();
        view!(d.efc_R, n.min(d.nefc as usize))
    }

    /// Number of constraint rows in the current constraint set (`mjData.nefc`).
    pub fn nefc(&self) -> usize {
        self.raw().nefc as usize
    }

    /// Constraint Jacobian rows `start..start + count` (row-major, `count` × nv), computed
    /// by the last [`Data::step1`] / [`Data::forward`]; `None` for sparse Jacobians (see
    /// [`Data::equality_jacobian`]) or rows out of range.
    pub fn constraint_rows(&self, start: usize, count: usize) -> Option<&[f64]> {
        // SAFETY: model pointer valid for the lifetime of self.
        let sparse = unsafe { sys::mj_isSparse(self.model.ptr) } != 0;
        let d = self.raw();
        if sparse || start + count > d.nefc as usize {
            return None;
        }
        let nv = self.model.nv();
        Some(&view!(d.efc_J, d.nefc as usize * nv)[start * nv..(start + count) * nv])
    }

    /// The constraint rows of contact `i`: `(first efc row, number of rows)`, or `None` when
    /// the contact has none (excluded, or beyond the constraint set). With pyramidal cones a
    /// contact of dimension `dim > 1` has `2 (dim − 1)` rows, pyramid edges in pairs
    /// `J_n ± μ_k J_tk`; otherwise `dim` rows, the normal first.
    pub fn contact_rows(&self, i: usize) -> Option<(usize, usize)> {
        let cs: &[sys::mjContact] = view!(self.raw().contact, self.raw().ncon);
        let c = &cs[i];
        if c.exclude != 0 || c.efc_address < 0 {
            return None;
        }
        let dim = c.dim as usize;
        let pyramidal = self.model.raw().opt.cone == sys::mjtCone__mjCONE_PYRAMIDAL as c_int;
        let rows = if pyramidal && dim > 1 {
            2 * (dim - 1)
        } else {
            dim
        };
        Some((c.efc_address as usize, rows))
    }

    /// Number of contacts in the current state.
    pub fn ncon(&self) -> usize {
        self.raw().ncon as usize
    }

    /// Contact `i` (0 ≤ i < [`Data::ncon`]).
    pub fn contact(&self, i: usize) -> Contact {
        let cs: &[sys::mjContact] = view!(self.raw().contact, self.raw().ncon);
        let c = &cs[i];
        Contact {
            geom1: c.geom1 as usize,
            geom2: c.geom2 as usize,
            dist: c.dist,
            pos: c.pos,
            frame: c.frame,
            excluded: c.exclude != 0,
        }
    }

    /// The geom pair of contact `i` without copying the rest.
    pub fn contact_geoms(&self, i: usize) -> (usize, usize) {
        let cs: &[sys::mjContact] = view!(self.raw().contact, self.raw().ncon);
        (cs[i].geom1 as usize, cs[i].geom2 as usize)
    }

    /// Force/torque of contact `i` in its contact frame (`mj_contactForce`): [normal, t1, t2,
    /// torsion, roll1, roll2]. A positive normal force pushes geom2 along the normal
    /// (from geom1 towards geom2).
    pub fn contact_force(&self, i: usize) -> [f64; 6] {
        assert!(
            i < self.ncon(),
            "contact index {i} out of range ({} contacts)",
            self.ncon()
        );
        let mut f = [0.0; 6];
        // SAFETY: i is a valid contact index and f has room for 6 values.
        unsafe { sys::mj_contactForce(self.model.ptr, self.ptr, i as c_int, f.as_mut_ptr()) };
        f
    }

    /// Translational (3×nv) and rotational (3×nv) Jacobians of site `site`, row-major,
    /// written into the caller's buffers (no allocation).
    pub fn jac_site(&self, site: usize, jacp: &mut [f64], jacr: &mut [f64]) {
        let nv = self.model.nv();
        assert!(site < self.model.nsite(), "site id {site} out of range");
        assert!(
            jacp.len() >= 3 * nv && jacr.len() >= 3 * nv,
            "Jacobian buffers need 3*nv = {} values",
            3 * nv
        );
        // SAFETY: site id valid; buffers hold at least 3*nv values each.
        unsafe {
            sys::mj_jacSite(
                self.model.ptr,
                self.ptr,
                jacp.as_mut_ptr(),
                jacr.as_mut_ptr(),
                site as c_int,
            )
        }
    }

    /// Like [`Data::jac_site`] for the origin of body `body`.
    pub fn jac_body(&self, body: usize, jacp: &mut [f64], jacr: &mut [f64]) {
        let nv = self.model.nv();
        assert!(body < self.model.nbody(), "body id {body} out of range");
        assert!(
            jacp.len() >= 3 * nv && jacr.len() >= 3 * nv,
            "Jacobian buffers need 3*nv = {} values",
            3 * nv
        );
        // SAFETY: body id valid; buffers hold at least 3*nv values each.
        unsafe {
            sys::mj_jacBody(
                self.model.ptr,
                self.ptr,
                jacp.as_mut_ptr(),
                jacr.as_mut_ptr(),
                body as c_int,
            )
        }
    }

    /// Solves `M x = y` for `n` right-hand sides (`mj_solveM`), with the factorisation of the
    /// joint-space inertia computed by the last [`Data::step1`] / [`Data::forward`]. `y` and
    /// `x` hold `n` vectors of length nv one after another. `x` and `y` may not overlap.
    pub fn solve_m(&mut self, x: &mut [f64], y: &[f64], n: usize) {
        let nv = self.model.nv();
        assert!(
            x.len() >= n * nv && y.len() >= n * nv,
            "solve_m needs {n}×nv = {} values in x and y",
            n * nv
        );
        // SAFETY: model and data belong together; x and y hold n·nv values each and are
        // distinct borrows; mj_solveM only reads qLD/qLDiagInv, which step1/forward computed.
        unsafe {
            sys::mj_solveM(
                self.model.ptr,
                self.ptr,
                x.as_mut_ptr(),
                y.as_ptr(),
                n as c_int,
            )
        }
    }

    /// `res = M vec` with the joint-space inertia of the last [`Data::step1`] /
    /// [`Data::forward`] (`mj_mulM`); both slices hold nv values.
    pub fn mul_m(&self, res: &mut [f64], vec: &[f64]) {
        let nv = self.model.nv();
        assert!(
            res.len() >= nv && vec.len() >= nv,
            "mul_m needs nv = {nv} values"
        );
        // SAFETY: model and data belong together; res and vec hold nv values each and are
        // distinct borrows; mj_mulM only reads qM.
        unsafe { sys::mj_mulM(self.model.ptr, self.ptr, res.as_mut_ptr(), vec.as_ptr()) }
    }

    /// 6-D velocity of body `body` at its centre of mass, world-oriented: [angular 3, linear 3].
    pub fn body_velocity(&self, body: usize) -> [f64; 6] {
        assert!(body < self.model.nbody(), "body id {body} out of range");
        let mut v = [0.0; 6];
        // SAFETY: body id valid, v has room for 6 values; flg_local = 0 (world frame).
        unsafe {
            sys::mj_objectVelocity(
                self.model.ptr,
                self.ptr,
                sys::mjtObj__mjOBJ_BODY as c_int,
                body as c_int,
                v.as_mut_ptr(),
                0,
            )
        };
        v
    }

    /// Copies the complete dynamic state into `out` (cleared first): time, qpos, qvel, act,
    /// ctrl, qacc_warmstart, qfrc_applied, xfrc_applied, mocap_pos, mocap_quat. Restoring it
    /// with [`Data::set_state`] makes the next steps bitwise identical.
    pub fn get_state(&self, out: &mut Vec<f64>) {
        out.clear();
        out.push(self.time());
        out.extend_from_slice(self.qpos());
        out.extend_from_slice(self.qvel());
        out.extend_from_slice(self.act());
        out.extend_from_slice(self.ctrl());
        out.extend_from_slice(self.qacc_warmstart());
        out.extend_from_slice(self.qfrc_applied());
        out.extend_from_slice(self.xfrc_applied());
        out.extend_from_slice(self.mocap_pos());
        out.extend_from_slice(self.mocap_quat());
    }

    /// Length of the vector written by [`Data::get_state`].
    pub fn state_len(&self) -> usize {
        let m = &self.model;
        1 + m.nq() + 2 * m.nv() + m.na() + m.nu() + m.nv() + 6 * m.nbody() + 7 * m.nmocap()
    }

    /// Restores a state captured by [`Data::get_state`] and recomputes derived quantities
    /// (`mj_forward`).
    pub fn set_state(&mut self, s: &[f64]) -> Result<()> {
        if s.len() != self.state_len() {
            return Err(MjError::Invalid(format!(
                "physics state has {} values, this model needs {}",
                s.len(),
                self.state_len()
            )));
        }
        self.set_time(s[0]);
        let mut off = 1;
        let mut take = |dst: &mut [f64]| {
            dst.copy_from_slice(&s[off..off + dst.len()]);
            off += dst.len();
        };
        take(self.qpos_mut());
        take(self.qvel_mut());
        take(self.act_mut());
        take(self.ctrl_mut());
        take(self.qacc_warmstart_mut());
        take(self.qfrc_applied_mut());
        take(self.xfrc_applied_mut());
        take(self.mocap_pos_mut());
        take(self.mocap_quat_mut());
        self.forward();
        // mj_forward normalises free-joint quaternions in qpos in place; put back the exact
        // captured values so that a restored state steps exactly like the original.
        let nq = self.qpos().len();
        self.qpos_mut().copy_from_slice(&s[1..1 + nq]);
        Ok(())
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
