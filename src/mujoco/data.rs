//! Owned simulation state: [`Data`] (`mjData`) with borrowed views of its arrays, stepping,
//! state capture and restore, contacts and warnings.
#![allow(unsafe_code)]

use super::*;

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
    /// Whether the contact lies in a geom's gap: apart by more than `margin − gap` where
    /// one of its geoms has a gap (never in a model without gaps). MuJoCo 2.2 may still give
    /// such a contact constraint rows; [`Data::release_contact`] takes their force away.
    pub in_gap: bool,
}

/// Owned simulation state (`mjData`) of one [`Model`]; keeps the model alive. Freed on drop.
pub struct Data {
    pub(super) model: Arc<Model>,
    pub(super) ptr: *mut sys::mjData,
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
    /// Passive forces (springs, damping) of the current state (`mj_fwdVelocity`).
    qfrc_passive = |m: &sys::mjModel| m.nv;
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
    /// The most of its stack this `mjData` has used since the last reset, in `f64`s
    /// (`maxuse_stack`).
    pub fn max_stack_use(&self) -> usize {
        self.raw().maxuse_stack as usize
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

    /// Stage `t`'s accumulated time since the timers were last cleared (all zero unless
    /// [`super::timer::enable_timers`] was called).
    pub fn timer(&self, t: super::timer::Timer) -> super::timer::TimerStat {
        let stat = &self.raw().timer[t.index()];
        super::timer::TimerStat {
            seconds: stat.duration,
            calls: stat.number.max(0) as u64,
        }
    }

    /// Iterations the constraint solver took in the last step (`mjData.solver_iter`).
    pub fn solver_iterations(&self) -> usize {
        self.raw().solver_iter.max(0) as usize
    }

    /// Clears every stage timer ([`Data::timer`]).
    pub fn clear_timers(&mut self) {
        // SAFETY: self.ptr is a valid mjData owned by self; `timer` is a fixed-size array
        // inside it, written here while no MuJoCo call runs on this Data.
        let d = unsafe { &mut *self.ptr };
        for stat in d.timer.iter_mut() {
            stat.duration = 0.0;
            stat.number = 0;
        }
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

    /// Switches contact `i` off for the coming [`Data::step2`]: the constraint solver gives
    /// its rows no force (impedance `efc_D` 0, regulariser `efc_R` MuJoCo's largest value).
    /// Call between [`Data::step1`] and [`Data::step2`]. Returns false (and changes nothing)
    /// when the contact has no rows.
    pub fn release_contact(&mut self, i: usize) -> bool {
        if i >= self.ncon() {
            return false;
        }
        let Some((row0, rows)) = self.contact_rows(i) else {
            return false;
        };
        let nefc = self.nefc();
        if row0 + rows > nefc {
            return false;
        }
        let (pd, pr) = (self.raw().efc_D, self.raw().efc_R);
        let d: &mut [f64] = view_mut!(pd, nefc);
        d[row0..row0 + rows].fill(0.0);
        let r: &mut [f64] = view_mut!(pr, nefc);
        r[row0..row0 + rows].fill(sys::mjMAXVAL);
        true
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
            in_gap: {
                let gap = self.model.geom_gap();
                (gap[c.geom1 as usize] > 0.0 || gap[c.geom2 as usize] > 0.0)
                    && c.dist > c.includemargin
            },
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

    /// Panics unless `jacp` and `jacr` hold 3×nv values each (a caller's bug).
    fn check_jacobian_buffers(&self, jacp: &[f64], jacr: &[f64]) {
        let nv = self.model.nv();
        assert!(
            jacp.len() >= 3 * nv && jacr.len() >= 3 * nv,
            "Jacobian buffers need 3*nv = {} values",
            3 * nv
        );
    }

    /// Translational (3×nv) and rotational (3×nv) Jacobians of site `site`, row-major,
    /// written into the caller's buffers (no allocation).
    pub fn jac_site(&self, site: usize, jacp: &mut [f64], jacr: &mut [f64]) {
        assert!(site < self.model.nsite(), "site id {site} out of range");
        self.check_jacobian_buffers(jacp, jacr);
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
        assert!(body < self.model.nbody(), "body id {body} out of range");
        self.check_jacobian_buffers(jacp, jacr);
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

    /// Translational and rotational Jacobians (3×nv each, row-major) of the world point
    /// `point` moving with body `body` (`mj_jac`), at the kinematics of the last
    /// [`Data::step1`] / [`Data::forward`]; written into the caller's buffers.
    pub fn jac_point(&self, body: usize, point: [f64; 3], jacp: &mut [f64], jacr: &mut [f64]) {
        assert!(body < self.model.nbody(), "body id {body} out of range");
        self.check_jacobian_buffers(jacp, jacr);
        // SAFETY: body id valid; buffers hold at least 3*nv values each; point holds 3.
        unsafe {
            sys::mj_jac(
                self.model.ptr,
                self.ptr,
                jacp.as_mut_ptr(),
                jacr.as_mut_ptr(),
                point.as_ptr(),
                body as c_int,
            )
        }
    }

    /// The dense joint-space inertia (nv×nv, row-major) of the last [`Data::step1`] /
    /// [`Data::forward`] (`mj_fullM`), armature included.
    pub fn full_m(&self, dst: &mut [f64]) {
        let nv = self.model.nv();
        assert!(
            dst.len() >= nv * nv,
            "full_m needs nv*nv = {} values",
            nv * nv
        );
        // SAFETY: dst holds nv*nv values; mj_fullM only reads qM.
        unsafe { sys::mj_fullM(self.model.ptr, dst.as_mut_ptr(), (*self.ptr).qM) }
    }

    /// Advances the positions `qpos` (nq values) by the velocities `qvel` (nv) over `dt`
    /// (`mj_integratePos`: quaternions of free and ball joints on the sphere).
    pub fn integrate_pos(&self, qpos: &mut [f64], qvel: &[f64], dt: f64) {
        let (nq, nv) = (self.model.nq(), self.model.nv());
        assert!(
            qpos.len() >= nq && qvel.len() >= nv,
            "integrate_pos needs nq = {nq} positions and nv = {nv} velocities"
        );
        // SAFETY: qpos holds nq values and qvel nv; mj_integratePos reads only the model.
        unsafe { sys::mj_integratePos(self.model.ptr, qpos.as_mut_ptr(), qvel.as_ptr(), dt) }
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

    /// Columns of `M⁻¹` at `units`, with the factorisation of the last [`Data::step1`] /
    /// [`Data::forward`]: `x[k·n + c]` becomes `(M⁻¹)[k, units[c]]` (n = `units.len()`; nv
    /// rows of n, row k for dof k). `trees` lists, ascending, every dof of the kinematic
    /// trees the units lie in (with each dof its ancestors and descendants); the other rows
    /// are zero, as they are in `M⁻¹`.
    ///
    /// The same arithmetic as [`Data::solve_m`] on the unit vectors (`mj_solveLD`'s
    /// operations on each entry in its order, bit for bit), without the work that a unit
    /// vector makes void: the backward pass visits only each unit's ancestors, where alone
    /// its vector is not zero, and the other passes only the units' trees, all columns side
    /// by side. Panics on a dof out of range or `x` shorter than `nv·n`.
    pub fn solve_m_units(&self, x: &mut [f64], units: &[usize], trees: &[usize]) {
        let m = &*self.model;
        let (nv, n) = (m.nv(), units.len());
        assert!(
            x.len() >= nv * n,
            "solve_m_units needs nv×{n} = {} values in x",
            nv * n
        );
        let (madr, parent, simple) = (m.dof_madr(), m.dof_parentid(), m.dof_simplenum());
        let raw = self.raw();
        let ld: &[f64] = view!(raw.qLD, m.n_m());
        let diag_inv: &[f64] = view!(raw.qLDiagInv, nv);
        let x = &mut x[..nv * n];
        x.fill(0.0);
        for (c, &u) in units.iter().enumerate() {
            x[u * n + c] = 1.0;
            // x ← L'⁻¹ x: only the unit's ancestors are ever non-zero, visited from the
            // unit up as MuJoCo's descending loop meets them.
            let mut i = u as c_int;
            while i >= 0 {
                let iu = i as usize;
                let tmp = x[iu * n + c];
                if simple[iu] == 0 && tmp != 0.0 {
                    let mut adr = madr[iu] as usize + 1;
                    let mut j = parent[iu];
                    while j >= 0 {
                        x[j as usize * n + c] -= ld[adr] * tmp;
                        adr += 1;
                        j = parent[j as usize];
                    }
                }
                i = parent[iu];
            }
        }
        // x ← D⁻¹ x, then x ← L⁻¹ x over the trees, a row (all columns) at a time.
        for &k in trees {
            for v in &mut x[k * n..(k + 1) * n] {
                *v *= diag_inv[k];
            }
        }
        for &k in trees {
            if simple[k] != 0 {
                continue;
            }
            // A dof's ancestors come before it.
            let (above, rest) = x.split_at_mut(k * n);
            let row = &mut rest[..n];
            let mut adr = madr[k] as usize + 1;
            let mut j = parent[k];
            while j >= 0 {
                let (l, ju) = (ld[adr], j as usize);
                for (v, a) in row.iter_mut().zip(&above[ju * n..(ju + 1) * n]) {
                    *v -= l * a;
                }
                adr += 1;
                j = parent[ju];
            }
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
