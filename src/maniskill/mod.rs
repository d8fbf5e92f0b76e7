//! Interoperation with ManiSkill 3's own data: reference trajectories recorded from
//! ManiSkill ([`reference`](mod@reference)), the step-by-step comparison of mjskill against them
//! ([`fidelity`]) and the outcome agreement of fixed action sequences ([`outcome`]).
pub mod fidelity;
pub mod outcome;
pub mod reference;
