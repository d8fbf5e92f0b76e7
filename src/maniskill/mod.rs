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
