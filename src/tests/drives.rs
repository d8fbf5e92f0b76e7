//! The drives' two shortcuts (docs/speed.md, "The drives' own MuJoCo calls") give MuJoCo's
//! own results bit for bit, on every robot, mid-motion, with a prop in the scene (a second
//! kinematic tree, carrying its weight as an applied wrench):
//! * the columns of `M⁻¹` that the drives read, solved only where a unit vector is not zero
//!   ([`Data::solve_m_units`]), against `mj_solveM` of the unit vectors;
//! * the robot's unconstrained acceleration from its smooth forces alone
//!   (`Drives::unconstrained_acceleration`), against `mj_fwdActuation` and
//!   `mj_fwdAcceleration`, and MuJoCo's again once a robot link carries a wrench.
use rand::{Rng, SeedableRng};

use crate::mujoco::Data;
use crate::robots::RobotId;

use super::common;

/// Substeps run before each comparison, with random drive targets.
const SUBSTEPS: usize = 40;

/// Every robot's table scene with a free box, driven through random targets for a while and
/// stopped after `mj_step1` (the factorisation and forces the drives see).
fn scenes() -> impl Iterator<Item = (RobotId, Data, crate::controllers::Drives)> {
    RobotId::ALL.into_iter().map(|robot| {
        let spec = robot.spec();
        let (_, _, mut d, mut drives) = common::table_scene_with(spec, |s| {
            s.add_box("box", [0.02; 3], [1.0, 0.0, 0.0, 1.0], [0.3, 0.2, 0.02])
        });
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for (k, &q) in spec.table_qpos.iter().enumerate() {
            drives.set_joint_target(k, q + rng.random_range(-0.3..0.3), 0.0);
        }
        common::run(&mut d, &mut drives, SUBSTEPS);
        d.step1();
        (robot, d, drives)
    })
}

#[test]
fn the_drives_columns_of_the_inverse_inertia_are_mujocos_bit_for_bit() {
    for (robot, mut d, drives) in scenes() {
        let nv = d.model().nv();
        let units: Vec<usize> = drives.tree_dofs().to_vec();
        let n = units.len();
        assert!(n > 0 && n < nv, "{robot:?}: the box is a tree of its own");
        let mut unit = vec![0.0; n * nv];
        for (c, &u) in units.iter().enumerate() {
            unit[c * nv + u] = 1.0;
        }
        let mut want = vec![0.0; n * nv];
        d.solve_m(&mut want, &unit, n);
        let mut got = vec![f64::NAN; n * nv];
        d.solve_m_units(&mut got, &units, drives.tree_dofs());
        for (c, &u) in units.iter().enumerate() {
            for k in 0..nv {
                let (g, w) = (got[k * n + c], want[c * nv + k]);
                assert_eq!(
                    g.to_bits(),
                    w.to_bits(),
                    "{robot:?}: (M⁻¹)[{k}, {u}] = {g}, mj_solveM {w}"
                );
            }
        }
        // A coupled arm: the columns are not merely the diagonal.
        let off_diagonal = (1..n).any(|c| got[units[0] * n + c] != 0.0);
        assert!(off_diagonal, "{robot:?}");
    }
}

#[test]
fn the_unconstrained_acceleration_shortcut_is_mujocos_bit_for_bit() {
    for (robot, d, mut drives) in scenes() {
        assert!(
            drives.drives_only(),
            "{robot:?}: an actuator that is no drive"
        );
        let dofs = drives.tree_dofs().to_vec();
        let mut fast = d.clone();
        let got = drives.unconstrained_acceleration(&mut fast, true).to_vec();
        let mut slow = d.clone();
        let want = drives.unconstrained_acceleration(&mut slow, false).to_vec();
        for &k in &dofs {
            assert_eq!(
                got[k].to_bits(),
                want[k].to_bits(),
                "{robot:?}: dof {k}: {} against MuJoCo's {}",
                got[k],
                want[k]
            );
        }
        assert!(dofs.iter().any(|&k| want[k].abs() > 1e-6), "{robot:?}");
        // A wrench on a robot link reaches the arm: the shortcut steps aside and MuJoCo
        // computes it.
        let link = d.model().dof_bodyid()[*dofs.last().unwrap()] as usize;
        let mut pushed = d.clone();
        pushed.xfrc_applied_mut()[6 * link..6 * link + 3].copy_from_slice(&[0.0, 0.0, 5.0]);
        let free = got;
        let mut slow = pushed.clone();
        let want = drives.unconstrained_acceleration(&mut slow, false).to_vec();
        let got = drives
            .unconstrained_acceleration(&mut pushed, true)
            .to_vec();
        assert!(
            dofs.iter().any(|&k| want[k] != free[k]),
            "{robot:?}: the wrench moves nothing"
        );
        for &k in &dofs {
            assert_eq!(got[k].to_bits(), want[k].to_bits(), "{robot:?}: dof {k}");
        }
    }
}
