//! Editing a compiled model's geometry in place, for the tasks whose shapes change every
//! episode (ManiSkill's reconfiguration, e.g. PegInsertionSide-v1's peg and hole): a model is
//! cloned before it is edited when other handles share it ([`Data::edit_model`]), box geoms
//! are resized and moved ([`Model::set_box_geom`]), a body's mass and inertia are set
//! ([`Model::set_body_inertia`]), and the quantities the compiler derives from them are
//! recomputed with `mj_setConst`. [`Model::to_mjb`] serialises a model, so that a test can
//! check an edited model against one compiled with the same shapes, byte for byte.
#![allow(unsafe_code)]

use std::sync::Arc;

use super::*;

impl Clone for Model {
    fn clone(&self) -> Model {
        // SAFETY: self.ptr is a valid model; with a null destination mj_copyModel allocates a
        // new model of the same sizes and copies every array into it.
        let ptr = unsafe { sys::mj_copyModel(std::ptr::null_mut(), self.ptr) };
        assert!(
            !ptr.is_null(),
            "MuJoCo could not allocate a copy of the model"
        );
        Model { ptr }
    }
}

impl Model {
    /// Resizes box geom `g` to half extents `half` and moves it to `pos` in its body frame;
    /// its bounding-sphere radius follows, as the compiler computes it. An error names a geom
    /// that is not a box or a size that is not positive and finite.
    pub fn set_box_geom(&mut self, g: GeomId, half: [f64; 3], pos: [f64; 3]) -> Result<()> {
        let i = g.index();
        if i >= self.ngeom() || self.geom_type()[i] != GEOM_BOX {
            return Err(MjError::Invalid(format!("geom {i} is not a box geom")));
        }
        if !half.iter().all(|h| h.is_finite() && *h > 0.0) || !pos.iter().all(|p| p.is_finite()) {
            return Err(MjError::Invalid(format!(
                "box geom {i}: half extents {half:?} must be positive and finite, position {pos:?} finite"
            )));
        }
        let n = self.ngeom();
        let m = self.raw_mut();
        view_mut!(m.geom_size, n * 3)[3 * i..3 * i + 3].copy_from_slice(&half);
        view_mut!(m.geom_pos, n * 3)[3 * i..3 * i + 3].copy_from_slice(&pos);
        view_mut!(m.geom_rbound, n)[i] =
            (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
        Ok(())
    }

    /// Sets body `b`'s mass and its diagonal inertia (in the body's inertial frame, which is
    /// left as it is). An error names a world body or a value that is not positive and finite.
    pub fn set_body_inertia(&mut self, b: BodyId, mass: f64, inertia: [f64; 3]) -> Result<()> {
        let i = b.index();
        if i == 0 || i >= self.nbody() {
            return Err(MjError::Invalid(format!(
                "body {i} is not a movable body of this model"
            )));
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !(positive(mass) && inertia.iter().all(|&x| positive(x))) {
            return Err(MjError::Invalid(format!(
                "body {i}: mass {mass} and inertia {inertia:?} must be positive and finite"
            )));
        }
        let n = self.nbody();
        let m = self.raw_mut();
        view_mut!(m.body_mass, n)[i] = mass;
        view_mut!(m.body_inertia, n * 3)[3 * i..3 * i + 3].copy_from_slice(&inertia);
        Ok(())
    }

    /// Sets geom `g`'s collision `margin` and `gap` (m): MuJoCo reports its contacts from
    /// `margin` apart, and those farther than `margin − gap` lie in its gap
    /// ([`Contact::in_gap`]; the pinch replica's speculative contacts). An error names a
    /// geom outside the model or a value that is negative or not finite, or a gap above the
    /// margin.
    pub fn set_geom_margin(&mut self, g: GeomId, margin: f64, gap: f64) -> Result<()> {
        let i = g.index();
        let n = self.ngeom();
        if i >= n {
            return Err(MjError::Invalid(format!("geom {i} is not in this model")));
        }
        let valid = |x: f64| x.is_finite() && x >= 0.0;
        if !(valid(margin) && valid(gap) && gap <= margin) {
            return Err(MjError::Invalid(format!(
                "geom {i}: margin {margin} and gap {gap} must be finite, non-negative, and the gap at most the margin"
            )));
        }
        let m = self.raw_mut();
        view_mut!(m.geom_margin, n)[i] = margin;
        view_mut!(m.geom_gap, n)[i] = gap;
        Ok(())
    }

    /// The model in MuJoCo's binary MJB format (`mj_saveModel` into memory): equal bytes mean
    /// equal models, names and every compiled quantity included.
    pub fn to_mjb(&self) -> Vec<u8> {
        // SAFETY: self.ptr is a valid model; mj_sizeModel only reads it.
        let size = unsafe { sys::mj_sizeModel(self.ptr) }.max(0) as usize;
        let mut buf = vec![0u8; size];
        // SAFETY: buf holds exactly mj_sizeModel bytes, the size mj_saveModel writes; a null
        // file name makes it write into the buffer only.
        unsafe {
            sys::mj_saveModel(
                self.ptr,
                std::ptr::null(),
                buf.as_mut_ptr().cast(),
                size as c_int,
            )
        };
        buf
    }

    fn raw_mut(&mut self) -> &mut sys::mjModel {
        // SAFETY: ptr is non-null, valid for the lifetime of self and exclusively borrowed.
        unsafe { &mut *self.ptr }
    }
}

impl Data {
    /// Edits the model this data steps: `edit` changes its geometry (the setters above), then
    /// `mj_setConst` recomputes what the compiler derives from it at the reference
    /// configuration (subtree masses, the constraint scaling `invweight0`, statistics). The
    /// model is cloned first when another handle shares it, so an [`Arc<Model>`] held
    /// elsewhere never changes under its holder. The data's state is left at the model's
    /// reference configuration (`mj_resetData`: `qpos0`, zero velocities and applied forces,
    /// mocap bodies at their model poses): callers set a new state afterwards, as a reset
    /// does. Sizes cannot change, so the data stays valid for it.
    pub fn edit_model<T>(&mut self, edit: impl FnOnce(&mut Model) -> Result<T>) -> Result<T> {
        let model = Arc::make_mut(&mut self.model);
        let out = edit(model)?;
        // SAFETY: model.ptr and self.ptr are valid, and self.ptr was allocated for a model of
        // the same sizes (a clone or the model itself, whose sizes an edit never changes).
        // mj_setConst reads the data's mocap poses, which the compiler's run finds at the
        // model's: the data is reset first, as the compiler's is fresh.
        unsafe {
            sys::mj_resetData(model.ptr, self.ptr);
            sys::mj_setConst(model.ptr, self.ptr);
        }
        Ok(out)
    }
}
