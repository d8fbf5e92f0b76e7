//! Interoperation with ManiSkill 3's own data: reference trajectories recorded from
//! ManiSkill ([`reference`](mod@reference)) and the step-by-step comparison of mjskill against them
//! ([`fidelity`]).
pub mod fidelity;
pub mod reference;
