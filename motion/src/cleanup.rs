//! The cleanup applied to decoded motion before users get it: a light temporal smoothing (no
//! frame-to-frame jumps), then feet that plant. Planted feet are found from the decoded feet
//! themselves ([`crate::contact`]); unless the root's path is known, the root travels so that
//! feet planted together stop sliding (a walk looped in place walks) and is lowered or raised so that planted feet stand on
//! the floor ([`Cleanup::floor`]: y = 0 for soles, higher for a rig whose leg ends are hocks),
//! and each planted foot is held at one spot for its whole contact by two-bone IK
//! ([`crate::ik`]), blended in and out over a few frames. A rig without legs is only smoothed.
//!
//! It works on cleaned motion (diameter 1, Y up, translation on the root only), the form the
//! models decode to.

use crate::contact::{ContactRule, Foot, contacts, find_feet, foot_points, ground_height, runs};
use crate::kinematics::{Transform, all_global_transforms, global_transforms};
use crate::motion::Motion;
use glam::{Quat, Vec3};

/// How decoded motion is cleaned up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cleanup {
    /// Standard deviation of the temporal smoothing, in seconds (0: none).
    pub smoothing: f32,
    /// When a foot counts as planted.
    pub rule: ContactRule,
    /// Seconds over which a planted foot's lock fades in before and out after its contact.
    pub blend: f32,
    /// The height (diameters) planted feet's contact points stand at above y = 0: 0 for soles,
    /// more for leg ends above the ground (real clips' [`crate::quality::Quality::foot_ground`]).
    pub floor: f32,
    /// Whether the root keeps its path and height, and planted feet are held where they stand
    /// rather than on the floor: for motion whose root is known (a real clip's tokens carry it),
    /// where turning every slide back would add up to a path that leaves the clip's. Contacts
    /// are then read against the floor, or the clip's own ground where that lies above it (a
    /// foot that sinks below the floor in a few frames does not make the others too high to
    /// plant). Otherwise the root travels so that feet planted together stop sliding, and rises
    /// or sinks so that they stand on the floor, and contacts are read against the clip's own
    /// ground, wherever it lies.
    pub keep_root: bool,
}

impl Default for Cleanup {
    /// Smoothing of one frame at 30 fps (it removes an alternation between frames and leaves a
    /// step's shape), a blend of three frames, and a root that moves with the planted feet.
    fn default() -> Self {
        Cleanup { smoothing: 1.0 / 30.0, rule: ContactRule::default(), blend: 0.1, floor: 0.0, keep_root: false }
    }
}

/// What the cleanup did, for the quality report.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Planting {
    /// The feet found (0 for a rig without legs: only smoothed).
    pub feet: usize,
    /// The fraction of foot-frames planted.
    pub planted: f32,
}

impl Cleanup {
    /// The motion smoothed and with its feet planted, and what was done.
    pub fn apply(&self, motion: &Motion) -> (Motion, Planting) {
        let smoothed = smooth(motion, self.smoothing * motion.fps() as f32);
        let feet = find_feet(&smoothed);
        if feet.is_empty() || smoothed.frames() < 2 {
            return (smoothed, Planting::default());
        }
        let skeleton = smoothed.skeleton().clone();
        let (n, frames) = (skeleton.len(), smoothed.frames());
        let globals = all_global_transforms(&smoothed);
        let points = foot_points(&smoothed, &feet, &globals);
        let scale = skeleton.diameter();
        // Where the root keeps its height (decoded from a real clip's tokens, in the frame the
        // tokenizer reads clips in, whose floor is y = 0), feet that sink below the floor in
        // some frames do not lower the ground the others are read against.
        let ground = ground_height(&points, feet.len()) / scale;
        let ground = if self.keep_root { ground.max(0.0) } else { ground };
        let unit_points: Vec<Vec3> = points.iter().map(|p| *p / scale).collect();
        let planted = contacts(&unit_points, feet.len(), smoothed.fps() as f32, ground, &self.rule);
        let floor = self.floor * scale;
        let (_, frame_time, mut rotations, mut translations) = smoothed.into_parts();
        // The whole body moves with the root: its feet's points with it.
        let mut points = points;
        if !self.keep_root {
            for (f, way) in root_travel(&points, &planted, feet.len()).iter().enumerate() {
                translations[f * n] += *way;
                for p in &mut points[f * feet.len()..(f + 1) * feet.len()] {
                    *p += *way;
                }
            }
            let shift = root_shift(&points, &planted, feet.len(), floor, 2.0 * motion.fps() as f32 / 30.0);
            for (f, s) in shift.iter().enumerate() {
                translations[f * n].y += s;
            }
        }
        let floor = (!self.keep_root).then_some(floor);
        let blend = (self.blend * motion.fps() as f32).round() as usize;
        let locks: Vec<Vec<Option<(Vec3, f32)>>> =
            planted.iter().enumerate().map(|(k, p)| locks(&points, feet.len(), k, p, blend, floor)).collect();
        let mut pose = Vec::with_capacity(n);
        for f in 0..frames {
            let (r, t) = (&mut rotations[f * n..(f + 1) * n], &translations[f * n..(f + 1) * n]);
            for (k, foot) in feet.iter().enumerate() {
                let Some((spot, weight)) = locks[k][f] else { continue };
                global_transforms(&skeleton, r, t, &mut pose);
                plant(foot, &skeleton, r, &pose, spot, weight);
            }
        }
        let report = Planting {
            feet: feet.len(),
            planted: planted.iter().flatten().filter(|&&p| p).count() as f32 / (frames * feet.len()) as f32,
        };
        let motion = Motion::new(skeleton, frame_time, rotations, translations).expect("shapes unchanged");
        (motion, report)
    }
}

/// Moves one foot's contact point `weight` of the way to `spot` by turning its chain.
fn plant(
    foot: &Foot,
    skeleton: &crate::skeleton::Skeleton,
    rotations: &mut [Quat],
    pose: &[Transform],
    spot: Vec3,
    weight: f32,
) {
    let point = foot.point(skeleton, pose);
    let target = point.lerp(spot, weight);
    let ankle = foot.chain.ankle_position(skeleton, pose) + (target - point);
    foot.chain.reach(skeleton, rotations, pose, ankle, pose[0].rotation * Vec3::Z);
}

/// For every frame, where the root must move up or down so that the lowest planted foot stands
/// at `floor`: measured at frames with a planted foot, interpolated between them, held at the
/// ends, then smoothed (standard deviation `sigma` frames). Zero when no foot is ever planted.
fn root_shift(points: &[Vec3], planted: &[Vec<bool>], feet: usize, floor: f32, sigma: f32) -> Vec<f32> {
    let frames = points.len() / feet;
    let measured: Vec<Option<f32>> = (0..frames)
        .map(|f| (0..feet).filter(|&k| planted[k][f]).map(|k| floor - points[f * feet + k].y).reduce(f32::max))
        .collect();
    gaussian(&filled(&measured), sigma)
}

/// For every frame, how far (horizontally) the root must have travelled since the first so that
/// planted feet stop sliding together: at each step with feet planted on both of its frames,
/// the slide of the foot that slides least, turned back. A walk looped in place (its stance
/// foot sliding back under a still root) then walks, and a foot that already holds still keeps
/// the root where it is. Steps without planted feet go at the speed of their neighbours
/// (interpolated, held at the ends).
fn root_travel(points: &[Vec3], planted: &[Vec<bool>], feet: usize) -> Vec<Vec3> {
    let frames = points.len() / feet;
    let at = |f: usize, k: usize| points[f * feet + k];
    let steps: Vec<Option<Vec3>> = (1..frames)
        .map(|f| {
            (0..feet)
                .filter(|&k| planted[k][f] && planted[k][f - 1])
                .map(|k| (at(f - 1, k) - at(f, k)).with_y(0.0))
                .min_by(|a, b| a.length().total_cmp(&b.length()))
        })
        .collect();
    let x = filled(&steps.iter().map(|s| s.map(|v| v.x)).collect::<Vec<_>>());
    let z = filled(&steps.iter().map(|s| s.map(|v| v.z)).collect::<Vec<_>>());
    let mut way = Vec::with_capacity(frames);
    way.push(Vec3::ZERO);
    for (dx, dz) in x.into_iter().zip(z) {
        let last = *way.last().expect("one frame in");
        way.push(last + Vec3::new(dx, 0.0, dz));
    }
    way
}

/// Values known at some indices, linearly interpolated between them and held at the ends;
/// all zero when none is known.
fn filled(measured: &[Option<f32>]) -> Vec<f32> {
    let known: Vec<(usize, f32)> = measured.iter().enumerate().filter_map(|(f, m)| m.map(|v| (f, v))).collect();
    (0..measured.len())
        .map(|f| {
            let after = known.partition_point(|k| k.0 < f);
            match (after.checked_sub(1).map(|i| known[i]), known.get(after)) {
                (_, Some(&(g, v))) if g == f => v,
                (Some((a, va)), Some(&(b, vb))) => va + (vb - va) * (f - a) as f32 / (b - a) as f32,
                (Some((_, v)), None) | (None, Some(&(_, v))) => v,
                (None, None) => 0.0,
            }
        })
        .collect()
}

/// For one foot, every frame's lock: the spot it is held at (the mean of its contact points
/// over the contact, at `floor` when there is one) and how strongly (1 inside the contact, fading over `blend`
/// frames on either side), or `None` where it moves freely.
fn locks(
    points: &[Vec3],
    feet: usize,
    k: usize,
    planted: &[bool],
    blend: usize,
    floor: Option<f32>,
) -> Vec<Option<(Vec3, f32)>> {
    let frames = planted.len();
    let mut out: Vec<Option<(Vec3, f32)>> = vec![None; frames];
    for run in runs(planted) {
        let mean = run.clone().map(|f| points[f * feet + k]).sum::<Vec3>() / run.len() as f32;
        let spot = floor.map_or(mean, |y| mean.with_y(y));
        let first = run.start.saturating_sub(blend);
        let last = (run.end + blend).min(frames);
        for (f, slot) in out.iter_mut().enumerate().take(last).skip(first) {
            let distance = if f < run.start { run.start - f } else { (f + 1).saturating_sub(run.end) };
            let weight = smoothstep(1.0 - distance as f32 / (blend + 1) as f32);
            if slot.is_none_or(|(_, w)| w < weight) {
                *slot = Some((spot, weight));
            }
        }
    }
    out
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A Gaussian filter over a sequence (standard deviation `sigma` samples, the ends held).
fn gaussian(values: &[f32], sigma: f32) -> Vec<f32> {
    let weights = kernel(sigma);
    let reach = weights.len() / 2;
    let last = values.len().saturating_sub(1) as isize;
    (0..values.len())
        .map(|f| {
            weights
                .iter()
                .enumerate()
                .map(|(i, w)| w * values[(f as isize + i as isize - reach as isize).clamp(0, last) as usize])
                .sum()
        })
        .collect()
}

/// Normalised Gaussian weights over +-3 sigma (a single 1 for sigma near zero).
fn kernel(sigma: f32) -> Vec<f32> {
    if sigma < 0.05 {
        return vec![1.0];
    }
    let reach = (3.0 * sigma).ceil() as isize;
    let raw: Vec<f32> = (-reach..=reach).map(|i| (-0.5 * (i as f32 / sigma).powi(2)).exp()).collect();
    let total: f32 = raw.iter().sum();
    raw.into_iter().map(|w| w / total).collect()
}

/// Every joint's rotation and the root's translation filtered over time with a Gaussian of
/// `sigma` frames. Rotations are averaged as quaternions on one hemisphere and normalised,
/// which for neighbouring frames is the rotation average to second order.
pub fn smooth(motion: &Motion, sigma: f32) -> Motion {
    let weights = kernel(sigma);
    if weights.len() == 1 || motion.frames() < 2 {
        return motion.clone();
    }
    let (skeleton, frame_time, mut rotations, mut translations) = motion.clone().into_parts();
    let (n, frames) = (skeleton.len(), motion.frames());
    let reach = weights.len() / 2;
    let at = |f: usize, i: usize| (f as isize + i as isize - reach as isize).clamp(0, frames as isize - 1) as usize;
    let roots: Vec<Vec3> = (0..frames).map(|f| translations[f * n]).collect();
    for f in 0..frames {
        translations[f * n] = weights.iter().enumerate().map(|(i, w)| *w * roots[at(f, i)]).sum();
    }
    for j in 0..n {
        let mut series: Vec<Quat> = (0..frames).map(|f| rotations[f * n + j]).collect();
        for f in 1..frames {
            if series[f].dot(series[f - 1]) < 0.0 {
                series[f] = -series[f];
            }
        }
        for f in 0..frames {
            let sum = weights
                .iter()
                .enumerate()
                .fold(glam::Vec4::ZERO, |s, (i, w)| s + *w * glam::Vec4::from(series[at(f, i)]));
            rotations[f * n + j] = Quat::from_vec4(sum).normalize();
        }
    }
    Motion::new(skeleton, frame_time, rotations, translations).expect("shapes unchanged")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::tests::biped;
    use crate::kinematics::all_joint_positions;

    /// The biped walking in place badly: floating 0.08 above the floor, its left foot sliding
    /// forward 0.02 per frame while low, its knees bending and straightening, for 30 frames.
    fn floating_slide() -> Motion {
        sliding_walk(|_| 0.08)
    }

    /// [`floating_slide`] with the root `lift(f)` above standing height in frame `f`.
    fn sliding_walk(lift: impl Fn(usize) -> f32) -> Motion {
        let stand = biped("Leg", "Foot");
        let (skeleton, _, _, _) = stand.clone().into_parts();
        let n = skeleton.len();
        let (mut rotations, mut translations) = (Vec::new(), Vec::new());
        for f in 0..30 {
            let phase = f as f32 / 30.0 * std::f32::consts::TAU;
            for j in 0..n {
                let r = match skeleton.joint(j).name.as_str() {
                    // The left leg swings forward and back while its foot stays low: it slides.
                    "LeftUpLeg" => Quat::from_rotation_x(-0.3 * phase.sin()),
                    "RightUpLeg" => Quat::from_rotation_x(-0.2),
                    "RightLeg" => Quat::from_rotation_x(0.4),
                    _ => Quat::IDENTITY,
                };
                rotations.push(r);
                translations.push(if j == 0 { Vec3::new(0.0, 0.95 + lift(f), 0.0) } else { skeleton.joint(j).offset });
            }
        }
        Motion::new(skeleton, 1.0 / 30.0, rotations, translations).unwrap()
    }

    #[test]
    fn a_kept_root_plants_feet_near_the_floor_though_two_frames_sink_below_it() {
        // Decoded with its root kept, the walk stands 0.02 diameters above the floor, and its
        // first two frames sink 0.1 below it: the clip's own ground (its 5th percentile) lies
        // 0.1 down, and read against it no foot of the other frames is low enough to plant.
        let diameter = sliding_walk(|_| 0.0).skeleton().diameter();
        let motion = sliding_walk(|f| if f < 2 { -0.1 * diameter } else { 0.02 * diameter });
        let kept = Cleanup { smoothing: 0.0, keep_root: true, ..Cleanup::default() };
        let (held, report) = kept.apply(&motion);
        assert!(report.planted > 0.6, "{report:?}");
        for f in 0..30 {
            assert_eq!(held.translations(f)[0], motion.translations(f)[0], "frame {f}: the root is kept");
        }
        // With the root free to rise and sink, the clip's own ground is what its feet stand on.
        let (_, free) = Cleanup { keep_root: false, ..kept }.apply(&motion);
        assert!(free.planted < 0.2, "{free:?}");
    }

    #[test]
    fn planted_feet_stand_on_the_floor_and_stop_sliding() {
        let motion = floating_slide();
        let diameter = motion.skeleton().diameter();
        let cleanup = Cleanup { smoothing: 0.0, ..Cleanup::default() };
        let (planted, report) = cleanup.apply(&motion);
        assert_eq!(report.feet, 2);
        let feet = find_feet(&planted);
        let point = |m: &Motion, f: usize, k: usize| {
            let globals = all_global_transforms(m);
            let n = m.skeleton().len();
            feet[k].point(m.skeleton(), &globals[f * n..(f + 1) * n])
        };
        // The right foot (bent leg, still) is planted the whole clip, on the floor, not at 0.08.
        for f in 0..30 {
            let p = point(&planted, f, 1);
            assert!(p.y.abs() < 2e-3 * diameter, "frame {f}: {p}");
        }
        // Before: the left toe's lowest frames slide; after, its planted frames hold one spot.
        let before: Vec<f32> = (0..30).map(|f| point(&motion, f, 0).z).collect();
        let spread =
            |zs: &[f32]| zs.iter().cloned().fold(f32::MIN, f32::max) - zs.iter().cloned().fold(f32::MAX, f32::min);
        assert!(spread(&before) > 0.1 * diameter);
        let left = contacts(
            &(0..30).map(|f| point(&planted, f, 0) / diameter).collect::<Vec<_>>(),
            1,
            30.0,
            0.0,
            &ContactRule::default(),
        );
        for run in runs(&left[0]).into_iter().filter(|r| r.len() > 6) {
            let inner: Vec<f32> = (run.start + 3..run.end - 3).map(|f| point(&planted, f, 0).z).collect();
            assert!(spread(&inner) < 1e-3 * diameter, "{run:?}: {inner:?}");
        }
        // Nothing but the legs and the root's height changed.
        for f in 0..30 {
            let (a, b) = (all_joint_positions(&motion.slice(f, 1)), all_joint_positions(&planted.slice(f, 1)));
            let shift = b[0].y - a[0].y;
            assert!((b[8].y - a[8].y - shift).abs() < 1e-5 && b[8].x == a[8].x, "the head follows the root only");
        }
    }

    #[test]
    fn a_walk_looped_in_place_travels_on_its_planted_feet() {
        // Standing on both feet, both thighs swing back by 0.3 rad over one second: the soles
        // (0.85 below the hips, 0.15 ahead) slide back under a still root, as on a treadmill.
        let stand = biped("Leg", "Foot");
        let (skeleton, _, _, _) = stand.into_parts();
        let n = skeleton.len();
        let (mut rotations, mut translations) = (Vec::new(), Vec::new());
        for f in 0..31 {
            for j in 0..n {
                let thigh = skeleton.joint(j).name.ends_with("UpLeg");
                rotations.push(if thigh { Quat::from_rotation_x(0.3 * f as f32 / 30.0) } else { Quat::IDENTITY });
                translations.push(if j == 0 { Vec3::new(0.0, 0.95, 0.0) } else { skeleton.joint(j).offset });
            }
        }
        let motion = Motion::new(skeleton, 1.0 / 30.0, rotations, translations).unwrap();
        let (walked, report) = Cleanup { smoothing: 0.0, ..Cleanup::default() }.apply(&motion);
        assert_eq!(report.planted, 1.0, "{report:?}");
        // The root moves forward by the soles' slide, and the soles hold still.
        let sole_z = |a: f32| -0.85 * a.sin() + 0.15 * a.cos();
        let root = walked.translations(30)[0];
        assert!((root.z - (sole_z(0.0) - sole_z(0.3))).abs() < 1e-4 && root.x.abs() < 1e-6, "{root}");
        let feet = find_feet(&walked);
        let globals = all_global_transforms(&walked);
        let tolerance = 1e-3 * walked.skeleton().diameter();
        for f in 0..31 {
            let sole = feet[0].point(walked.skeleton(), &globals[f * n..(f + 1) * n]);
            assert!((sole.z - sole_z(0.0)).abs() < tolerance, "frame {f}: {sole}");
        }
        // Where the root's path is known, it keeps it.
        let (kept, _) = Cleanup { smoothing: 0.0, keep_root: true, ..Cleanup::default() }.apply(&motion);
        for f in 0..31 {
            assert_eq!(motion.translations(f)[0], kept.translations(f)[0], "frame {f}");
        }
    }

    #[test]
    fn smoothing_removes_an_alternation_and_keeps_a_steady_turn() {
        let stand = biped("Leg", "Foot");
        let (skeleton, _, _, _) = stand.into_parts();
        let n = skeleton.len();
        let (mut rotations, mut translations) = (Vec::new(), Vec::new());
        for f in 0..20 {
            for j in 0..n {
                // The head turns steadily; the spine flickers by +-0.1 rad every other frame.
                let r = match j {
                    8 => Quat::from_rotation_y(0.05 * f as f32),
                    7 => Quat::from_rotation_x(if f % 2 == 0 { 0.1 } else { -0.1 }),
                    _ => Quat::IDENTITY,
                };
                rotations.push(r);
                translations.push(if j == 0 { Vec3::new(0.0, 0.95, 0.0) } else { skeleton.joint(j).offset });
            }
        }
        let motion = Motion::new(skeleton, 1.0 / 30.0, rotations, translations).unwrap();
        let smoothed = smooth(&motion, 1.0);
        for f in 4..16 {
            let head = smoothed.rotations(f)[8];
            assert!(head.angle_between(Quat::from_rotation_y(0.05 * f as f32)) < 1e-3, "a steady turn stays");
            assert!(smoothed.rotations(f)[7].angle_between(Quat::IDENTITY) < 0.03, "the flicker is gone");
        }
    }

    #[test]
    fn a_rig_without_legs_is_only_smoothed() {
        let motion = biped("Fin", "Flap");
        let (out, report) = Cleanup { smoothing: 0.0, ..Cleanup::default() }.apply(&motion);
        assert_eq!(report, Planting::default());
        assert_eq!(out.all_translations(), motion.all_translations());
    }
}
