//! Interoperation with ManiSkill 3's own data: reference trajectories recorded from
//! ManiSkill ([`reference`](mod@reference)), the step-by-step comparison of mjskill against them
//! ([`fidelity`]), the outcome agreement of fixed action sequences ([`outcome`]), and
//! mjskill's camera images against ManiSkill's ([`images`], reading numpy archives with
//! [`npz`]).
pub mod fidelity;
pub mod images;
pub mod npz;
pub mod outcome;
pub mod reference;

/// The name under which mjskill (and ManiSkill's state dict) knows a ManiSkill scene actor: a
/// task that builds its actors per env (PegInsertionSide-v1) names them `peg_0` in its scene
/// and `peg` (merged) in its state dict. `known` tells which names exist; a name that is known,
/// or has no merged form that is, comes back as it is.
pub fn merged_actor_name(name: &str, known: impl Fn(&str) -> bool) -> &str {
    match name.strip_suffix("_0") {
        Some(merged) if !known(name) && known(merged) => merged,
        _ => name,
    }
}
