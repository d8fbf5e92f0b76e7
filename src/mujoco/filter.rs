//! MuJoCo's contact filter, with a cheaper test in front of its box narrow phase.
//!
//! MuJoCo 2.2 pairs the world body with every other body and prunes geom pairs only by their
//! bounding spheres. The table is a world box of 2.4 × 1.2 × 0.9 m, whose bounding sphere holds
//! the whole robot, so every robot geom met the table in the narrow phase (`mjc_BoxBox`, or
//! libccd's MPR for a cylinder) at every substep: about 2 µs of a Panda substep's 20, for no
//! contact. MuJoCo lets a process replace its contact filter (`mjcb_contactfilter`, called for
//! every geom pair the broad phase passes, before the bounding-sphere test). The filter
//! installed here is MuJoCo 2.2.2's own filter (`mj_contactFilter`: contype/conaffinity, same
//! weld body, parent filter) followed by a slab test: a pair is also skipped when the other
//! geom's bounding sphere lies beyond one of a box's three face slabs by more than the contact
//! margin plus [`SLACK`].
//!
//! **It changes no contact.** A box's face normals are separating axes that `mjc_BoxBox` tests
//! first, returning no contact when the other box's extent along one of them (at most its
//! bounding radius) lies more than the margin beyond the face; the other narrow-phase functions
//! (sphere, capsule, libccd's MPR for cylinders and meshes) return contacts only within the
//! margin of the true distance, which the slab gap bounds from below. [`SLACK`] (1 mm) leaves
//! rounding and MPR's tolerance (10⁻⁶ m) far behind. So the contact list, and with it the whole
//! simulation, is the same bit for bit (`tests/contact_filter.rs` compares trajectories with
//! the slab test on and off).
//!
//! The callback is process-wide: [`super::init`] installs it once, before any model is loaded.
//! Models of other code in the same process get MuJoCo's own filter decisions too, and the same
//! contacts. [`set_box_slab_test`] switches the slab test off and on (for tests and timing).
use std::os::raw::c_int;
use std::sync::atomic::{AtomicBool, Ordering};

use mujoco_sys as sys;

/// Extra distance (m) beyond the contact margin that a geom's bounding sphere must lie outside
/// a box's face slab for the pair to be skipped.
pub const SLACK: f64 = 1e-3;

static SLAB_TEST: AtomicBool = AtomicBool::new(true);

/// Switches the box slab test on or off for the whole process (on by default). Either way the
/// contacts are the same; off, MuJoCo's narrow phase runs for every pair its filter passes.
pub fn set_box_slab_test(on: bool) {
    SLAB_TEST.store(on, Ordering::Relaxed);
}

/// Whether the box slab test is on ([`set_box_slab_test`]).
pub fn box_slab_test() -> bool {
    SLAB_TEST.load(Ordering::Relaxed)
}

/// Installs [`contact_filter`] as MuJoCo's process-wide contact filter. Called once, from
/// [`super::init`].
pub(super) fn install() {
    // SAFETY: `mjcb_contactfilter` is a plain function-pointer global that MuJoCo only reads;
    // it is written once, from `init` under its OnceLock, before this module loads any model,
    // and `contact_filter` is a valid `mjfConFilt` for the life of the process.
    unsafe { sys::mjcb_contactfilter = Some(contact_filter) };
}

/// MuJoCo's `mjcb_contactfilter`: 1 skips the geom pair, 0 lets MuJoCo test it.
unsafe extern "C" fn contact_filter(
    m: *const sys::mjModel,
    d: *mut sys::mjData,
    g1: c_int,
    g2: c_int,
) -> c_int {
    // SAFETY: MuJoCo calls the filter from `mj_collideGeoms` with the model and data being
    // collided (both valid for the call, the data not written meanwhile) and two valid geom ids.
    let (m, d) = unsafe { (&*m, &*d) };
    let (g1, g2) = (g1 as usize, g2 as usize);
    // SAFETY: as above: the ids index the model's geom and body arrays.
    let skip = unsafe { mujoco_filter(m, g1, g2) }
        || (SLAB_TEST.load(Ordering::Relaxed)
            // SAFETY: as above; geom_xpos and geom_xmat are the positions of this collision.
            && unsafe { beyond_box(m, d, g1, g2) || beyond_box(m, d, g2, g1) });
    c_int::from(skip)
}

/// MuJoCo 2.2.2's built-in filter (`mj_contactFilter` as `mj_collideGeoms` calls it): true when
/// neither geom's contype meets the other's conaffinity, when both are welded to one body, or
/// when one's weld body is the other's weld parent (unless the parent filter is disabled or
/// either is welded to the world).
///
/// # Safety
/// `g1` and `g2` must be geom ids of `m`.
unsafe fn mujoco_filter(m: &sys::mjModel, g1: usize, g2: usize) -> bool {
    // SAFETY: the caller's ids index the geom arrays (ngeom long); body and weld ids that the
    // compiled model stores index the body arrays (nbody long).
    unsafe {
        let contype = |g: usize| *m.geom_contype.add(g);
        let conaffinity = |g: usize| *m.geom_conaffinity.add(g);
        if contype(g1) & conaffinity(g2) == 0 && contype(g2) & conaffinity(g1) == 0 {
            return true;
        }
        let weld = |g: usize| *m.body_weldid.add(*m.geom_bodyid.add(g) as usize);
        let (w1, w2) = (weld(g1), weld(g2));
        if w1 == w2 {
            return true;
        }
        let parent_weld = |w: c_int| *m.body_weldid.add(*m.body_parentid.add(w as usize) as usize);
        let filter_parent = m.opt.disableflags & sys::mjtDisableBit__mjDSBL_FILTERPARENT as c_int
            == 0
            && w1 != 0
            && w2 != 0;
        filter_parent && (w1 == parent_weld(w2) || w2 == parent_weld(w1))
    }
}

/// True when `other`'s bounding sphere lies beyond one of box `b`'s face slabs by more than the
/// pair's contact margin plus [`SLACK`]; false when `b` is not a box or `other` has no bounding
/// sphere (a plane or a height field).
///
/// # Safety
/// `b` and `other` must be geom ids of `m`, and `d` data of `m` after its kinematics.
unsafe fn beyond_box(m: &sys::mjModel, d: &sys::mjData, b: usize, other: usize) -> bool {
    // SAFETY: the caller's ids index the geom arrays: types, radii, margins (ngeom), sizes,
    // positions (3 per geom) and orientations (9 per geom).
    unsafe {
        if *m.geom_type.add(b) != sys::mjtGeom__mjGEOM_BOX as c_int {
            return false;
        }
        let radius = *m.geom_rbound.add(other);
        if radius <= 0.0 {
            return false;
        }
        let mut margin = m.geom_margin.add(b).read().max(*m.geom_margin.add(other));
        if m.opt.enableflags & sys::mjtEnableBit__mjENBL_OVERRIDE as c_int != 0 {
            margin = m.opt.o_margin;
        }
        let reach = radius + margin + SLACK;
        let pb = std::slice::from_raw_parts(d.geom_xpos.add(3 * b), 3);
        let po = std::slice::from_raw_parts(d.geom_xpos.add(3 * other), 3);
        let rot = std::slice::from_raw_parts(d.geom_xmat.add(9 * b), 9);
        let size = std::slice::from_raw_parts(m.geom_size.add(3 * b), 3);
        let dif = [po[0] - pb[0], po[1] - pb[1], po[2] - pb[2]];
        (0..3).any(|i| {
            // The offset along the box's axis i: column i of its world orientation.
            let along = dif[0] * rot[i] + dif[1] * rot[3 + i] + dif[2] * rot[6 + i];
            along.abs() - size[i] > reach
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mujoco::{Data, Model};
    use std::sync::Arc;

    /// A table box whose top is at z = 0, a free box (`b`, id 1) over it, and a free box
    /// (`c`, id 2) that only the table's contype meets.
    const SCENE: &str = r#"<mujoco>
      <worldbody>
        <geom name="table" type="box" size="0.5 0.5 0.1" pos="0 0 -0.1" margin="0.001"/>
        <body name="b" pos="0 0 0.3">
          <freejoint/>
          <geom name="b" type="box" size="0.05 0.05 0.05" mass="1"/>
        </body>
        <body name="c" pos="0 0 0.3">
          <freejoint/>
          <geom name="c" type="box" size="0.05 0.05 0.05" mass="1" contype="2" conaffinity="2"/>
        </body>
      </worldbody>
    </mujoco>"#;

    /// The filter's answer for geoms `g1`, `g2` with body `b` at height `z`, both ways round.
    fn skips(data: &mut Data, z: f64, g1: c_int, g2: c_int) -> bool {
        data.qpos_mut()[2] = z;
        data.forward();
        let (m, d) = (data.model().ptr, data.ptr);
        // SAFETY: m and d are a live model and its data after `forward`; the ids are its geoms.
        let (a, b) = unsafe { (contact_filter(m, d, g1, g2), contact_filter(m, d, g2, g1)) };
        assert_eq!(a, b, "the filter is symmetric");
        a == 1
    }

    #[test]
    fn the_slab_test_skips_only_pairs_beyond_the_margin() {
        crate::mujoco::init().unwrap();
        let model = Arc::new(Model::from_xml_string(SCENE, &[]).unwrap());
        let mut data = Data::new(model).unwrap();
        // Half height 0.05, bounding radius 0.0866, margin 0.001, slack 0.001: the box's
        // centre must be more than 0.0886 above the table top.
        assert!(skips(&mut data, 0.3, 0, 1), "far above the table");
        assert!(skips(&mut data, 0.0890, 0, 1), "just beyond the slab");
        assert!(!skips(&mut data, 0.0880, 0, 1), "within the slack");
        assert!(!skips(&mut data, 0.04, 0, 1), "resting on the table");
        // MuJoCo's own filter: contype 1 against conaffinity 2 and back.
        assert!(skips(&mut data, 0.04, 1, 2), "contype meets no conaffinity");
        set_box_slab_test(false);
        let far = skips(&mut data, 0.3, 0, 1);
        set_box_slab_test(true);
        assert!(
            !far,
            "with the slab test off, MuJoCo's narrow phase decides"
        );
    }
}
