//! anymo's motion data model, with no neural network in it.
//!
//! Everything anymo does starts here: BVH and glTF files become a [`skeleton::Skeleton`] and a
//! [`motion::Motion`]; [`kinematics`] turns local joint transforms into global positions;
//! [`features`] maps motion to the models' per-joint features and exactly back; [`reference`]
//! rebases motion onto a reference pose so no rig convention shows in it; [`prep`] cleans
//! and normalises clips for training without touching what users get back; [`metrics`] measures
//! reconstruction and transfer. [`contact`] finds any rig's feet and their ground contacts,
//! [`ik`] places a leg, [`cleanup`] smooths decoded motion and plants its feet, [`posture`]
//! stands a rest pose up, [`quality`] states how plausible a motion is, and [`activity`] what it
//! does (travel and turns against its facing, feet in the air, hands and head).
//!
//! ```
//! use anymo_motion::{bvh, kinematics, motion::Motion};
//!
//! let text = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n JOINT Head\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.0333333\n0 1 0 0 0 0 0 0 0\n";
//! let clip = bvh::parse_str(text)?;
//! let motion = Motion::from_bvh(&clip);
//! let head = kinematics::joint_positions(&motion, 0)[1];
//! assert_eq!(head, glam::Vec3::new(0.0, 2.0, 0.0));
//! # Ok::<(), anymo_motion::bvh::BvhError>(())
//! ```

pub mod activity;
pub mod bvh;
pub mod cleanup;
pub mod contact;
pub mod features;
pub mod gltf;
pub mod ik;
pub mod kinematics;
pub mod metrics;
pub mod motion;
pub mod posture;
pub mod prep;
pub mod quality;
pub mod reference;
pub mod rotation;
pub mod skeleton;
