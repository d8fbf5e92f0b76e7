//! Headless offscreen rendering with MuJoCo's own renderer (`mjv_*` scene, `mjr_*` context)
//! on an EGL context of Mesa's surfaceless platform (software rasteriser, no display, no GPU).
//!
//! * `libEGL.so.1` is loaded at run time (the `khronos-egl` crate over `libloading`), not
//!   linked: a program that never renders never touches EGL or GL, and a machine without them
//!   gets a [`RenderError::Unavailable`] naming the packages to install instead of a loader
//!   failure at start-up.
//! * One EGL display per process (initialised once, never terminated, because EGL displays
//!   are shared process-wide); every [`Renderer`] owns its own GL context.
//! * A GL context is current on at most one thread. A [`Renderer`] makes its context current
//!   at the start of every call and releases it before returning, so between calls it is
//!   current nowhere and the renderer can move to another thread (it is `Send`, not `Sync`).
//! * MuJoCo 2.2 kills the process when `mjr_makeContext` runs without a current context;
//!   the renderer checks `eglGetCurrentContext` before every `mjr_*` call.
//! * Frames are read back with `mjr_readPixels` (bottom row first) and flipped to top row
//!   first. Depth is converted from MuJoCo's non-linear [0, 1] depth buffer to metres along
//!   the optical axis (the camera-frame −z of the surface point, as ManiSkill's depth).
//! * Segmentation ([`Renderer::render_frame`] with a [`Segmentation`]) is a second pass of
//!   the same scene with MuJoCo's `mjRND_SEGMENT` + `mjRND_IDCOLOR` flags: every drawn
//!   `mjvGeom` is painted flat in the colour `segid + 1` (24 bits, background 0), which is
//!   decoded through the scene's geoms (`segid` → model geom id) and the caller's label
//!   table (model geom id → label). Geoms that are not drawn (groups switched off) never
//!   appear; decorations (no model geom) read as 0.
use std::ffi::c_int;
use std::sync::{Arc, Mutex, OnceLock};

use khronos_egl as egl;
use mujoco_sys as sys;

use super::{Data, Model};

/// The Debian packages headless rendering needs at run time.
pub const RENDER_PACKAGES: &str = "libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1";

/// `EGL_PLATFORM_SURFACELESS_MESA` (EGL_MESA_platform_surfaceless).
const PLATFORM_SURFACELESS_MESA: egl::Enum = 0x31DD;

/// Errors of the renderer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RenderError {
    /// No usable EGL / OpenGL on this machine.
    #[error(
        "headless rendering is unavailable: {0}; install the Debian packages {RENDER_PACKAGES} \
         (apt-get install -y {RENDER_PACKAGES}) or run `bash .ci/setup`"
    )]
    Unavailable(String),
    /// A bad argument (camera id, image size, buffer length).
    #[error("{0}")]
    Invalid(String),
    /// Too little address space left under the process's limit for a new GL context.
    #[error("cannot create a GL context: {0}")]
    Memory(String),
    /// EGL failed after the context was created.
    #[error("rendering failed: {0}")]
    Failed(String),
}

/// Render quality settings. The defaults favour speed: no shadows, no multisampling, no
/// reflections (software rasterisation pays heavily for each).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderOptions {
    /// Shadow mapping from the scene's lights (every light casts shadows when on).
    pub shadows: bool,
    /// Multisample anti-aliasing samples of the offscreen buffer (0 = off).
    pub msaa_samples: u32,
    /// Planar reflections of reflective materials.
    pub reflections: bool,
    /// Near and far clipping distances in metres (ManiSkill's cameras: 0.01 and 100).
    pub clip: (f64, f64),
    /// Tessellation of spheres, capsules and cylinders: slices around the axis (MuJoCo's
    /// `quality/numslices`, default 28; stacks are half as many, at least 4). Vertex work
    /// dominates software rendering: 12 slices draw the 128×128 sensor image about 1.8×
    /// faster than 28.
    pub slices: u32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            shadows: false,
            msaa_samples: 0,
            reflections: false,
            clip: (0.01, 100.0),
            slices: 12,
        }
    }
}

type EglInstance = egl::DynamicInstance<egl::EGL1_5>;

/// The process-wide EGL library, display and framebuffer configuration.
struct EglDisplay {
    egl: EglInstance,
    display: egl::Display,
    config: egl::Config,
}

// SAFETY: EGL display and config handles are process-wide objects that EGL allows to be used
// from any thread (EGL 1.5 §3: all EGL functions are thread-safe); the loaded library handle
// is immutable.
unsafe impl Send for EglDisplay {}
// SAFETY: see above; nothing in EglDisplay is mutated after initialisation.
unsafe impl Sync for EglDisplay {}

/// Why EGL could not be set up or a context made current. Kept (and cloned into every
/// [`RenderError`]) once per process, so the loader's error is held as its text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
enum EglError {
    /// libEGL.so.1 is missing or lacks EGL 1.5.
    #[error("cannot load libEGL.so.1 with EGL 1.5 ({0})")]
    Load(String),
    /// No surfaceless platform.
    #[error(
        "EGL offers no surfaceless platform (EGL_MESA_platform_surfaceless missing; Mesa's \
         EGL driver is not installed?); client extensions: {0:?}"
    )]
    NoSurfaceless(String),
    /// An EGL call failed.
    #[error("{call} failed: {source}{hint}")]
    Call {
        /// The call.
        call: &'static str,
        /// EGL's error.
        source: egl::Error,
        /// What is likely missing (may be empty).
        hint: &'static str,
    },
    /// No framebuffer configuration fits.
    #[error("no EGL config with desktop OpenGL, RGBA8, depth 24 and stencil 8")]
    NoConfig,
    /// The context is not current after making it so.
    #[error("the GL context is not current after eglMakeCurrent")]
    NotCurrent,
}

impl EglError {
    fn call(call: &'static str) -> impl FnOnce(egl::Error) -> EglError {
        move |source| EglError::Call {
            call,
            source,
            hint: "",
        }
    }
}

/// Address space a new GL context needs, with a margin (bytes): measured, each context after
/// the first takes 64 MB of new address space (one of glibc's malloc heaps, against 29 MB
/// resident), and 4 times that is required.
pub const GL_CONTEXT_ADDRESS_SPACE: u64 = 256 << 20;

/// Address space the first GL context of a process needs, with a margin (bytes): measured,
/// Mesa's EGL display, its llvmpipe rasteriser threads and the first context take 600 MB.
pub const FIRST_GL_CONTEXT_ADDRESS_SPACE: u64 = 768 << 20;

/// Whether this process has made a GL context.
static CONTEXT_MADE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Refuses to create a GL context with less than [`GL_CONTEXT_ADDRESS_SPACE`] (the first:
/// [`FIRST_GL_CONTEXT_ADDRESS_SPACE`]) of address space left under `RLIMIT_AS` (`prlimit
/// --as`, `ulimit -v`): Mesa does not check its allocations there and crashes the process
/// (SIGSEGV in `driCreateContextAttribs`), where a clean error is possible.
fn check_address_space(left: Option<super::limits::Headroom>) -> Result<(), RenderError> {
    let need = if CONTEXT_MADE.load(std::sync::atomic::Ordering::Relaxed) {
        GL_CONTEXT_ADDRESS_SPACE
    } else {
        FIRST_GL_CONTEXT_ADDRESS_SPACE
    };
    match left {
        Some(h) if h.bytes < need => Err(RenderError::Memory(format!(
            "a new GL context needs about {} MB of address space, and {} MB are left ({}); \
             raise the limit or make fewer rendering envs",
            need >> 20,
            h.bytes >> 20,
            h.source
        ))),
        _ => Ok(()),
    }
}

static EGL: OnceLock<Result<EglDisplay, EglError>> = OnceLock::new();
/// Serialises context creation: `mjr_makeContext` (re)loads MuJoCo's process-global GL
/// function table.
static CREATE: Mutex<()> = Mutex::new(());

fn init_egl() -> Result<EglDisplay, EglError> {
    // SAFETY: loads the system libEGL; the symbols are the standard EGL 1.5 entry points,
    // whose signatures khronos-egl declares.
    let egl = unsafe { EglInstance::load_required_from_filename("libEGL.so.1") }
        .map_err(|e| EglError::Load(e.to_string()))?;
    let ext = egl
        .query_string(None, egl::EXTENSIONS)
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !ext.contains("EGL_MESA_platform_surfaceless") {
        return Err(EglError::NoSurfaceless(ext));
    }
    // SAFETY: the surfaceless platform takes no native display (EGL_DEFAULT_DISPLAY = null).
    let display = unsafe {
        egl.get_platform_display(
            PLATFORM_SURFACELESS_MESA,
            egl::DEFAULT_DISPLAY,
            &[egl::ATTRIB_NONE],
        )
    }
    .map_err(EglError::call("eglGetPlatformDisplay(surfaceless)"))?;
    egl.initialize(display).map_err(|source| EglError::Call {
        call: "eglInitialize",
        source,
        hint: " (no Mesa DRI driver?)",
    })?;
    let attrs = [
        egl::SURFACE_TYPE,
        egl::PBUFFER_BIT,
        egl::RENDERABLE_TYPE,
        egl::OPENGL_BIT,
        egl::RED_SIZE,
        8,
        egl::GREEN_SIZE,
        8,
        egl::BLUE_SIZE,
        8,
        egl::ALPHA_SIZE,
        8,
        egl::DEPTH_SIZE,
        24,
        egl::STENCIL_SIZE,
        8,
        egl::NONE,
    ];
    let config = egl
        .choose_first_config(display, &attrs)
        .map_err(EglError::call("eglChooseConfig"))?
        .ok_or(EglError::NoConfig)?;
    Ok(EglDisplay {
        egl,
        display,
        config,
    })
}

fn egl_display() -> Result<&'static EglDisplay, RenderError> {
    EGL.get_or_init(init_egl)
        .as_ref()
        .map_err(|e| RenderError::Unavailable(e.to_string()))
}

/// Checks that headless rendering can start here (loads EGL and opens the display, once per
/// process). `Err` explains what is missing and which packages to install.
pub fn available() -> Result<(), RenderError> {
    egl_display().map(|_| ())
}

/// An offscreen renderer for one model: its own GL context, MuJoCo scene and render context.
pub struct Renderer {
    model: Arc<Model>,
    /// Bitwise copy of the model's `mjModel` header with the visual settings this renderer
    /// uses (buffer size, samples, shadow map, clip planes); its array pointers alias the
    /// model's buffer, which `model` keeps alive and which MuJoCo's renderer only reads.
    vis: Box<sys::mjModel>,
    egl: &'static EglDisplay,
    ctx: egl::Context,
    scn: Box<sys::mjvScene>,
    con: Box<sys::mjrContext>,
    opt: sys::mjvOption,
    cam: sys::mjvCamera,
    pert: sys::mjvPerturb,
    options: RenderOptions,
    row: Vec<u8>,
    rowf: Vec<f32>,
    /// Id colours of the segmentation pass (grown once to the largest image segmented).
    seg_rgb: Vec<u8>,
    /// Label of each scene geom by `segid` (`maxgeom` entries), rebuilt every segmented frame.
    seg_labels: Vec<i16>,
}

/// The segmentation output of [`Renderer::render_frame`]: `out` (H·W labels, top row first)
/// receives, per pixel, `labels[g]` of the model geom `g` drawn there, or 0 for the
/// background, for decorations and for geoms beyond `labels`.
#[derive(Debug)]
pub struct Segmentation<'a> {
    /// Label per model geom id (e.g. the id of the geom's body or actor).
    pub labels: &'a [i16],
    /// The label image, H·W, top row first.
    pub out: &'a mut [i16],
}

// SAFETY: the GL context is current on no thread between calls (every method releases it
// before returning, and `Drop` makes it current on the dropping thread), so the renderer may
// move between threads. The scene and render context are heap blocks owned exclusively here;
// `&self` methods touch no GL state, so no `Sync` is claimed.
unsafe impl Send for Renderer {}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("max_size", &self.max_size())
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

/// Makes `ctx` current on this thread and checks that it is.
fn make_current(e: &EglDisplay, ctx: egl::Context) -> Result<(), EglError> {
    // eglBindAPI is per thread; eglGetCurrentContext answers for the bound API.
    e.egl
        .bind_api(egl::OPENGL_API)
        .map_err(EglError::call("eglBindAPI(EGL_OPENGL_API)"))?;
    e.egl
        .make_current(e.display, None, None, Some(ctx))
        .map_err(EglError::call("eglMakeCurrent"))?;
    match e.egl.get_current_context() {
        Some(c) if c.as_ptr() == ctx.as_ptr() => Ok(()),
        _ => Err(EglError::NotCurrent),
    }
}

fn release(e: &EglDisplay) {
    // Releasing cannot meaningfully fail for a context current on this thread; a failure
    // would surface at the next make_current.
    let _ = e.egl.make_current(e.display, None, None, None);
}

/// `GL_TEXTURE_2D`, `GL_TEXTURE_MIN_FILTER`, `GL_LINEAR`.
const GL_TEXTURE_2D: u32 = 0x0DE1;
const GL_TEXTURE_MIN_FILTER: u32 = 0x2801;
const GL_LINEAR: i32 = 0x2601;

/// Switches every 2D texture of `con` from MuJoCo's trilinear mipmapped minification to
/// bilinear sampling of the full-resolution image (the context must be current). This is
/// closer to ManiSkill's renders, whose textures look sharper at a distance (the RGB
/// difference to ManiSkill's frames falls from 13.8 to 13.5), and cheaper for the software
/// rasteriser (the 512×512 frame draws about a quarter faster; docs/observations.md).
fn bilinear_textures(e: &EglDisplay, con: &sys::mjrContext) -> Result<(), RenderError> {
    let missing = |f: &str| RenderError::Unavailable(format!("OpenGL lacks {f}"));
    let bind = e
        .egl
        .get_proc_address("glBindTexture")
        .ok_or_else(|| missing("glBindTexture"))?;
    let param = e
        .egl
        .get_proc_address("glTexParameteri")
        .ok_or_else(|| missing("glTexParameteri"))?;
    type Bind = extern "system" fn(u32, u32);
    type Param = extern "system" fn(u32, u32, i32);
    // SAFETY: both are OpenGL 1.1 entry points with these C signatures
    // (`void glBindTexture(GLenum, GLuint)`, `void glTexParameteri(GLenum, GLenum, GLint)`);
    // EGL returned them for the current context.
    let (bind, param) = unsafe {
        (
            std::mem::transmute::<extern "system" fn(), Bind>(bind),
            std::mem::transmute::<extern "system" fn(), Param>(param),
        )
    };
    let n = (con.ntexture.max(0) as usize).min(con.texture.len());
    for i in 0..n {
        if con.textureType[i] == sys::mjtTexture__mjTEXTURE_2D as c_int {
            bind(GL_TEXTURE_2D, con.texture[i]);
            param(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
        }
    }
    bind(GL_TEXTURE_2D, 0);
    Ok(())
}

impl Renderer {
    /// Creates a renderer for `model` whose images may be up to `max_size` (width, height)
    /// pixels. Errors when EGL/GL is missing (naming the packages to install).
    pub fn new(
        model: Arc<Model>,
        max_size: (usize, usize),
        options: RenderOptions,
    ) -> Result<Renderer, RenderError> {
        let (w, h) = max_size;
        if w == 0 || h == 0 || w > 8192 || h > 8192 {
            return Err(RenderError::Invalid(format!(
                "render size {w}x{h} must be between 1x1 and 8192x8192"
            )));
        }
        let (near, far) = options.clip;
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far > near) {
            return Err(RenderError::Invalid(format!(
                "clip planes must satisfy 0 < near < far, got near {near}, far {far}"
            )));
        }
        if !(3..=100).contains(&options.slices) {
            return Err(RenderError::Invalid(format!(
                "slices {} is out of range (3 to 100)",
                options.slices
            )));
        }
        if options.msaa_samples > 16 {
            return Err(RenderError::Invalid(format!(
                "msaa_samples {} is out of range (0 = off, at most 16)",
                options.msaa_samples
            )));
        }
        super::init().map_err(|e| RenderError::Invalid(e.to_string()))?;
        // Before EGL is initialised too: Mesa's display and rasteriser threads are most of
        // what the first context takes.
        check_address_space(super::limits::address_space())?;
        let e = egl_display()?;
        let _guard = CREATE.lock().unwrap_or_else(|p| p.into_inner());
        check_address_space(super::limits::address_space())?;
        e.egl
            .bind_api(egl::OPENGL_API)
            .map_err(|err| RenderError::Unavailable(format!("eglBindAPI failed: {err}")))?;
        let ctx = e
            .egl
            .create_context(e.display, e.config, None, &[egl::NONE])
            .map_err(|err| {
                RenderError::Unavailable(format!("eglCreateContext (desktop GL) failed: {err}"))
            })?;
        CONTEXT_MADE.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Err(msg) = make_current(e, ctx) {
            let _ = e.egl.destroy_context(e.display, ctx);
            return Err(RenderError::Unavailable(msg.to_string()));
        }

        let mut vis = Box::new(*model.raw());
        let extent = model.raw().stat.extent.max(1e-9);
        {
            let v = &mut vis.vis;
            v.global.offwidth = v.global.offwidth.max(w as c_int);
            v.global.offheight = v.global.offheight.max(h as c_int);
            v.quality.offsamples = options.msaa_samples as c_int;
            v.quality.shadowsize = if options.shadows { 2048 } else { 0 };
            v.map.znear = (near / extent) as f32;
            v.map.zfar = (far / extent) as f32;
            v.quality.numslices = options.slices as c_int;
            v.quality.numstacks = (options.slices as c_int / 2).max(4);
        }
        // Plain C structs, zeroed by Default, then initialised by the mjv_default* calls.
        let mut scn: Box<sys::mjvScene> = Box::default();
        let mut con: Box<sys::mjrContext> = Box::default();
        let mut opt = sys::mjvOption::default();
        let mut cam = sys::mjvCamera::default();
        let mut pert = sys::mjvPerturb::default();
        let maxgeom = (2 * model.ngeom() + 100) as c_int;
        // SAFETY: `vis` is a valid mjModel header (see the field comment) and the context
        // made current above is current on this thread, as mjr_makeContext requires.
        unsafe {
            sys::mjv_defaultScene(&mut *scn);
            sys::mjv_defaultOption(&mut opt);
            sys::mjv_defaultCamera(&mut cam);
            sys::mjv_defaultPerturb(&mut pert);
            sys::mjr_defaultContext(&mut *con);
            sys::mjv_makeScene(&*vis, &mut *scn, maxgeom);
            sys::mjr_makeContext(&*vis, &mut *con, sys::mjtFontScale__mjFONTSCALE_50 as c_int);
            sys::mjr_setBuffer(sys::mjtFramebuffer__mjFB_OFFSCREEN as c_int, &mut *con);
        }
        // Still current: sample textures bilinearly from their full-resolution level.
        let filters = bilinear_textures(e, &con);
        release(e);
        opt.sitegroup = [0; 6];
        opt.jointgroup = [0; 6];
        opt.tendongroup = [0; 6];
        opt.actuatorgroup = [0; 6];
        cam.type_ = sys::mjtCamera__mjCAMERA_FIXED as c_int;
        scn.flags[sys::mjtRndFlag__mjRND_SHADOW as usize] = options.shadows as u8;
        scn.flags[sys::mjtRndFlag__mjRND_REFLECTION as usize] = options.reflections as u8;
        scn.flags[sys::mjtRndFlag__mjRND_SKYBOX as usize] = 0;
        let r = Renderer {
            model,
            vis,
            egl: e,
            ctx,
            scn,
            con,
            opt,
            cam,
            pert,
            options,
            row: vec![0; 3 * w],
            rowf: vec![0.0; w],
            seg_rgb: Vec::new(),
            seg_labels: vec![0; maxgeom as usize],
        };
        // Dropping `r` on an error frees the GL and MuJoCo contexts.
        filters?;
        if r.con.currentBuffer != sys::mjtFramebuffer__mjFB_OFFSCREEN as c_int
            || r.con.offWidth < w as c_int
            || r.con.offHeight < h as c_int
        {
            return Err(RenderError::Unavailable(format!(
                "MuJoCo could not create a {w}x{h} offscreen framebuffer (got {}x{})",
                r.con.offWidth, r.con.offHeight
            )));
        }
        Ok(r)
    }

    /// The largest image (width, height) this renderer can produce.
    pub fn max_size(&self) -> (usize, usize) {
        (self.con.offWidth as usize, self.con.offHeight as usize)
    }

    /// The quality settings.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// The model rendered.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// Renders the state in `data` through model camera `camera` into `rgb` (H·W·3 bytes,
    /// top row first) and/or `depth` (H·W metres along the optical axis; the far plane where
    /// nothing was drawn). `geom_groups[g]` says whether geoms of group g are drawn.
    /// Allocates nothing.
    pub fn render(
        &mut self,
        data: &mut Data,
        camera: usize,
        size: (usize, usize),
        geom_groups: [bool; 6],
        rgb: Option<&mut [u8]>,
        depth: Option<&mut [f32]>,
    ) -> Result<(), RenderError> {
        self.render_frame(data, camera, size, geom_groups, rgb, depth, None)
    }

    /// [`Renderer::render`] plus, optionally, a segmentation image (see [`Segmentation`]).
    /// The scene is built once; colour is one pass, segmentation another (depth comes from
    /// the first pass drawn). Segmentation is exact with any `msaa_samples` (MuJoCo turns
    /// multisampling off in that pass). After the first segmented frame of the largest size,
    /// allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn render_frame(
        &mut self,
        data: &mut Data,
        camera: usize,
        size: (usize, usize),
        geom_groups: [bool; 6],
        rgb: Option<&mut [u8]>,
        depth: Option<&mut [f32]>,
        seg: Option<Segmentation<'_>>,
    ) -> Result<(), RenderError> {
        let (w, h) = size;
        let (mw, mh) = self.max_size();
        if !Arc::ptr_eq(data.model(), &self.model) {
            return Err(RenderError::Invalid(
                "the data belongs to another model than the renderer".into(),
            ));
        }
        if camera >= self.model.ncam() {
            return Err(RenderError::Invalid(format!(
                "camera id {camera} out of range (the model has {} cameras)",
                self.model.ncam()
            )));
        }
        if w == 0 || h == 0 || w > mw || h > mh {
            return Err(RenderError::Invalid(format!(
                "image size {w}x{h} exceeds this renderer's {mw}x{mh} (or is empty)"
            )));
        }
        if rgb.as_ref().is_some_and(|b| b.len() != w * h * 3)
            || depth.as_ref().is_some_and(|b| b.len() != w * h)
            || seg.as_ref().is_some_and(|s| s.out.len() != w * h)
        {
            return Err(RenderError::Invalid(format!(
                "image buffers must hold {w}x{h}x3 bytes (rgb), {w}x{h} floats (depth) and \
                 {w}x{h} labels (segmentation)"
            )));
        }
        if seg.is_some() && self.seg_rgb.len() < w * h * 3 {
            self.seg_rgb.resize(w * h * 3, 0);
        }
        make_current(self.egl, self.ctx).map_err(|e| RenderError::Failed(e.to_string()))?;
        for (g, on) in self.opt.geomgroup.iter_mut().zip(geom_groups) {
            *g = on as u8;
        }
        self.cam.fixedcamid = camera as c_int;
        let viewport = sys::mjrRect {
            left: 0,
            bottom: 0,
            width: w as c_int,
            height: h as c_int,
        };
        let mut rgb = rgb;
        let mut depth = depth;
        let rgb_ptr = rgb
            .as_deref_mut()
            .map_or(std::ptr::null_mut(), |b| b.as_mut_ptr());
        let depth_ptr = depth
            .as_deref_mut()
            .map_or(std::ptr::null_mut(), |b| b.as_mut_ptr());
        let seg_ptr = if seg.is_some() {
            self.seg_rgb.as_mut_ptr()
        } else {
            std::ptr::null_mut()
        };
        let flags = [
            sys::mjtRndFlag__mjRND_SEGMENT as usize,
            sys::mjtRndFlag__mjRND_IDCOLOR as usize,
            sys::mjtRndFlag__mjRND_SHADOW as usize,
            sys::mjtRndFlag__mjRND_REFLECTION as usize,
        ];
        // SAFETY: model header, data, scene and context are valid and belong together; the
        // renderer's context is current on this thread (checked above); the buffers hold
        // w·h·3 bytes / w·h floats (checked above; `seg_rgb` was grown to w·h·3) and the
        // viewport lies inside the offscreen buffer. The pointers come from the exclusive
        // borrows `rgb`/`depth` and from `self.seg_rgb`, which outlive the calls and are not
        // touched otherwise until they return.
        unsafe {
            sys::mjv_updateScene(
                &*self.vis,
                data.ptr,
                &self.opt,
                &self.pert,
                &mut self.cam,
                sys::mjtCatBit__mjCAT_ALL as c_int,
                &mut *self.scn,
            );
            if self.options.shadows {
                let n = self.scn.nlight.max(0) as usize;
                for l in self.scn.lights.iter_mut().take(n) {
                    l.castshadow = 1;
                }
            }
            sys::mjr_setBuffer(sys::mjtFramebuffer__mjFB_OFFSCREEN as c_int, &mut *self.con);
            let mut depth_ptr = depth_ptr;
            if !rgb_ptr.is_null() || seg_ptr.is_null() {
                sys::mjr_render(viewport, &mut *self.scn, &*self.con);
                sys::mjr_readPixels(rgb_ptr, depth_ptr, viewport, &*self.con);
                depth_ptr = std::ptr::null_mut();
            }
            if !seg_ptr.is_null() {
                let saved = flags.map(|f| self.scn.flags[f]);
                self.scn.flags[flags[0]] = 1;
                self.scn.flags[flags[1]] = 1;
                self.scn.flags[flags[2]] = 0;
                self.scn.flags[flags[3]] = 0;
                sys::mjr_render(viewport, &mut *self.scn, &*self.con);
                sys::mjr_readPixels(seg_ptr, depth_ptr, viewport, &*self.con);
                for (f, v) in flags.iter().zip(saved) {
                    self.scn.flags[*f] = v;
                }
            }
        }
        release(self.egl);
        if let Some(buf) = rgb {
            flip_rows(buf, 3 * w, &mut self.row);
        }
        if let Some(buf) = depth {
            flip_rows(buf, w, &mut self.rowf);
            let c = &self.scn.camera[0];
            let (n, f) = (c.frustum_near as f64, c.frustum_far as f64);
            for d in buf.iter_mut() {
                *d = linear_depth(*d as f64, n, f) as f32;
            }
        }
        if let Some(s) = seg {
            self.decode_segmentation(w, h, s);
        }
        Ok(())
    }

    /// Turns the id colours of the last segmentation pass (bottom row first) into labels
    /// (top row first).
    fn decode_segmentation(&mut self, w: usize, h: usize, seg: Segmentation<'_>) {
        self.seg_labels.fill(0);
        let n = self.scn.ngeom.max(0) as usize;
        // SAFETY: `geoms` holds `maxgeom` initialised entries (mjv_makeScene) of which the
        // first `ngeom` were written by mjv_updateScene; nothing else aliases the scene.
        let geoms = unsafe { std::slice::from_raw_parts(self.scn.geoms, n) };
        let geom_obj = sys::mjtObj__mjOBJ_GEOM as c_int;
        for g in geoms {
            let Ok(segid) = usize::try_from(g.segid) else {
                continue;
            };
            if g.objtype != geom_obj {
                continue;
            }
            let label = usize::try_from(g.objid)
                .ok()
                .and_then(|id| seg.labels.get(id))
                .copied()
                .unwrap_or(0);
            if let Some(slot) = self.seg_labels.get_mut(segid) {
                *slot = label;
            }
        }
        let table = &self.seg_labels;
        for (r, out_row) in seg.out.chunks_exact_mut(w).enumerate() {
            let src = &self.seg_rgb[(h - 1 - r) * 3 * w..(h - r) * 3 * w];
            for (o, c) in out_row.iter_mut().zip(src.chunks_exact(3)) {
                let id = c[0] as usize | (c[1] as usize) << 8 | (c[2] as usize) << 16;
                *o = if id == 0 {
                    0
                } else {
                    table.get(id - 1).copied().unwrap_or(0)
                };
            }
        }
    }
}

/// Metres along the optical axis from a perspective depth-buffer value `d` in [0, 1] with
/// near/far planes `n`/`f` (OpenGL's default depth range).
pub fn linear_depth(d: f64, n: f64, f: f64) -> f64 {
    n * f / (f - d * (f - n))
}

/// Reverses the order of the rows (`stride` elements each) of `buf` in place.
fn flip_rows<T: Copy>(buf: &mut [T], stride: usize, tmp: &mut [T]) {
    let rows = buf.len() / stride;
    let tmp = &mut tmp[..stride];
    for r in 0..rows / 2 {
        let (a, b) = (r * stride, (rows - 1 - r) * stride);
        tmp.copy_from_slice(&buf[a..a + stride]);
        buf.copy_within(b..b + stride, a);
        buf[b..b + stride].copy_from_slice(tmp);
    }
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // SAFETY: the scene was made by mjv_makeScene and is freed once; it holds no GL state.
        unsafe { sys::mjv_freeScene(&mut *self.scn) };
        if make_current(self.egl, self.ctx).is_ok() {
            // SAFETY: the context that owns these GL objects is current on this thread.
            unsafe { sys::mjr_freeContext(&mut *self.con) };
            release(self.egl);
        }
        // Destroying the context frees its GL objects even if they were not freed above.
        let _ = self.egl.egl.destroy_context(self.egl.display, self.ctx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_linearisation_hits_the_planes() {
        assert!((linear_depth(0.0, 0.01, 100.0) - 0.01).abs() < 1e-12);
        assert!((linear_depth(1.0, 0.01, 100.0) - 100.0).abs() < 1e-9);
        // A point at z metres maps to d = f (z − n) / (z (f − n)); invert it back.
        let (n, f, z) = (0.01, 100.0, 0.7);
        let d = f * (z - n) / (z * (f - n));
        assert!((linear_depth(d, n, f) - z).abs() < 1e-12);
    }

    #[test]
    fn rows_flip_in_place() {
        let mut v = [1, 2, 3, 4, 5, 6];
        flip_rows(&mut v, 2, &mut [0; 2]);
        assert_eq!(v, [5, 6, 3, 4, 1, 2]);
    }

    #[test]
    fn unavailable_error_names_the_packages() {
        let msg = RenderError::Unavailable("cannot load libEGL.so.1".into()).to_string();
        for p in [
            "libegl1",
            "libegl-mesa0",
            "libgl1-mesa-dri",
            "libgbm1",
            "libEGL.so.1",
        ] {
            assert!(msg.contains(p), "{msg}");
        }
    }

    #[test]
    fn bad_options_are_rejected_before_touching_gl() {
        let m =
            Arc::new(Model::from_xml_string("<mujoco><worldbody/></mujoco>", &[]).expect("model"));
        let bad = RenderOptions {
            clip: (0.0, 1.0),
            ..Default::default()
        };
        let err = Renderer::new(m.clone(), (64, 64), bad).unwrap_err();
        assert!(err.to_string().contains("near"), "{err}");
        let err = Renderer::new(m, (0, 64), RenderOptions::default()).unwrap_err();
        assert!(err.to_string().contains("0x64"), "{err}");
    }
}
