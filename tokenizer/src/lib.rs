//! anymo's motion tokenizer: the skeleton graph encoder OwO ([`owo`]), the topology-agnostic
//! tokenizer TAT and its zero-padded baseline ([`tat`]), the training windows they learn from
//! ([`dataset`]), and the small neural toolkit ([`nn`]) and sentence encoder ([`text`]) that the
//! generator builds on too. Motion itself (files, kinematics, features) is `anymo-motion`'s.

pub mod dataset;
pub mod nn;
pub mod owo;
pub mod tat;
pub mod text;
