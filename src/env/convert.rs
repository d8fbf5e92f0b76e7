//! One env driven through another control mode of the same robot: an action of a source mode
//! turned into this env's mode by the joint targets it set (as ManiSkill's
//! `replay_trajectory --target-control-mode`), and the source env kept on this env's state.
//! `solvers::ModeConverted` runs the scripted solvers this way (docs/solvers.md, "In another
//! control mode").
use super::{Env, EnvError};

impl Env {
    /// Makes this env a copy of `other`, the same env and robot in any control mode: the
    /// episode's shapes (PegInsertionSide-v1's), the physics, the drives (targets and force
    /// law state), the step count, the finger forces, the seeds and the random streams. The targets this env's controller accumulates
    /// restart from the measured positions (as after a reset), so its next action acts from
    /// `other`'s state.
    pub fn sync_from(&mut self, other: &Env) -> Result<(), EnvError> {
        if (self.id, self.sim.spec.uid()) != (other.id, other.sim.spec.uid()) {
            return Err(EnvError::BadState(format!(
                "cannot follow {}/{} with {}/{}: the env and robot must be the same",
                other.id,
                other.sim.spec.uid(),
                self.id,
                self.sim.spec.uid()
            )));
        }
        // The episode's shapes first (PegInsertionSide-v1): writing them resets the data.
        self.adopt_geometry(&other.sim.task.geometry());
        let mut physics = Vec::with_capacity(other.sim.data.state_len());
        other.sim.data.get_state(&mut physics);
        self.sim
            .data
            .set_state(&physics)
            .map_err(|e| EnvError::BadState(e.to_string()))?;
        let sim = &mut self.sim;
        sim.controller
            .reset(&sim.robot.joints, &sim.data, &mut sim.drives);
        let mut drives = Vec::with_capacity(other.sim.drives.save_len());
        other.sim.drives.save(&mut drives);
        sim.drives.load(&drives);
        self.elapsed_steps = other.elapsed_steps;
        self.sim.finger_forces = other.sim.finger_forces;
        self.numpy = other.numpy.clone();
        self.torch_global = other.torch_global.clone();
        (self.main_seed, self.episode_seed) = (other.main_seed, other.episode_seed);
        self.main_numpy = other.main_numpy.clone();
        self.update_outputs();
        Ok(())
    }

    /// Writes into `out` the action of this env's control mode that has the effect
    /// `source_action` had on `source`'s last step (`source`: the same env and robot in
    /// another mode, stepped from this env's current state, e.g. after
    /// [`Env::sync_from`]). The parts the two modes share (the same kind and bounds, e.g. a
    /// gripper or Fetch's base) take `source_action`'s slice; every other part must be a
    /// joint position part (`pd_joint_pos`, `pd_joint_delta_pos`,
    /// `pd_joint_target_delta_pos`) and takes the action that sets its joints to the drive
    /// targets `source` set, clipped to its action bounds (a delta beyond them is not
    /// reached in one step).
    pub fn convert_action(
        &self,
        source: &Env,
        source_action: &[f32],
        out: &mut [f32],
    ) -> Result<(), EnvError> {
        let spec = self.sim.spec;
        let (mine, theirs) = (self.control_mode(), source.control_mode());
        let refuse = |what: String| {
            EnvError::ModeConversion(format!(
                "cannot convert {theirs} actions to {mine} for {}: {what}",
                spec.uid()
            ))
        };
        if spec.uid() != source.sim.spec.uid() || self.id != source.id {
            return Err(refuse(format!(
                "the source env is {}/{}",
                source.id,
                source.sim.spec.uid()
            )));
        }
        if source_action.len() != source.action_space().shape[0]
            || out.len() != self.action_space().shape[0]
        {
            return Err(refuse(format!(
                "actions of {} and {} values, expected {} and {}",
                source_action.len(),
                out.len(),
                source.action_space().shape[0],
                self.action_space().shape[0]
            )));
        }
        let (_, my_parts) = spec.control_mode(mine)?;
        let (_, their_parts) = spec.control_mode(theirs)?;
        let their_ranges = source.sim.controller.part_ranges();
        let copy = |name: &str| {
            let mine = my_parts.iter().find(|p| p.name == name)?;
            let k = their_parts.iter().position(|p| p.name == name)?;
            (their_parts[k] == *mine).then(|| &source_action[their_ranges[k].1.clone()])
        };
        let drives = &source.sim.drives;
        let target = |i: usize| drives.joint_target(i).map(|t| t.0);
        self.sim
            .controller
            .action_for_targets(&self.sim.robot.joints, &self.sim.data, &target, &copy, out)
            .map_err(|part| {
                refuse(format!(
                    "its {part} part takes neither the same action as in {theirs} nor joint \
                     positions (convert to pd_joint_pos, pd_joint_delta_pos or \
                     pd_joint_target_delta_pos)"
                ))
            })
    }
}
