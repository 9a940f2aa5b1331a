//! Properties of the reader and writer over generated input: any skeleton with any channel
//! layout and any finite values writes and reads back bit-identically; no input makes the
//! reader panic; the file's whitespace and number spelling do not change what it reads.

use anymo_motion::bvh::{self, Bvh, ReadOptions};
use anymo_motion::skeleton::{Axis, Channel, Channels, Joint, Skeleton};
use glam::Vec3;
use proptest::prelude::*;

fn channel_list() -> impl Strategy<Value = Vec<Channel>> {
    let all: Vec<Channel> =
        [Axis::X, Axis::Y, Axis::Z].into_iter().flat_map(|a| [Channel::Position(a), Channel::Rotation(a)]).collect();
    Just(all).prop_shuffle().prop_flat_map(|all| (0..=6usize).prop_map(move |n| all[..n].to_vec()))
}

fn finite() -> impl Strategy<Value = f32> {
    prop_oneof![any::<f32>().prop_filter("finite", |v| v.is_finite()), -1000.0f32..1000.0, Just(-0.0f32)]
}

fn skeleton() -> impl Strategy<Value = Skeleton> {
    (1..12usize)
        .prop_flat_map(|n| {
            (
                proptest::collection::vec(any::<prop::sample::Index>(), n),
                proptest::collection::vec(channel_list(), n),
                proptest::collection::vec([finite(), finite(), finite()], n),
                proptest::collection::vec(proptest::option::of([finite(), finite(), finite()]), n),
            )
        })
        .prop_map(|(parents, channels, offsets, ends)| {
            // Depth-first: each joint's parent is on the chain from the root to the joint before.
            let mut chain: Vec<usize> = Vec::new();
            let mut parent_of = Vec::new();
            for (i, pick) in parents.iter().enumerate() {
                if i == 0 {
                    parent_of.push(None);
                } else {
                    let keep = pick.index(chain.len()) + 1;
                    chain.truncate(keep);
                    parent_of.push(chain.last().copied());
                }
                chain.push(i);
            }
            let joints = (0..parents.len())
                .map(|i| Joint {
                    name: format!("joint {i}"),
                    parent: parent_of[i],
                    offset: Vec3::from_array(offsets[i]),
                    channels: Channels::new(channels[i].clone()).unwrap(),
                    end_site: ends[i].map(Vec3::from_array),
                })
                .collect();
            Skeleton::new(joints).unwrap()
        })
}

fn clip() -> impl Strategy<Value = Bvh> {
    (skeleton(), 0..5usize, 1e-4f64..1.0).prop_flat_map(|(skeleton, frames, frame_time)| {
        let count = frames * skeleton.channel_count();
        proptest::collection::vec(finite(), count)
            .prop_map(move |values| Bvh::new(skeleton.clone(), frame_time, frames, values).unwrap())
    })
}

fn bits(b: &Bvh) -> Vec<u32> {
    b.values().iter().map(|v| v.to_bits()).collect()
}

proptest! {
    #[test]
    fn any_clip_round_trips_bit_exactly(clip in clip()) {
        let mut text = Vec::new();
        bvh::write(&clip, &mut text).unwrap();
        let back = bvh::read(text.as_slice(), ReadOptions::default()).unwrap();
        prop_assert_eq!(&back, &clip);
        prop_assert_eq!(bits(&back), bits(&clip));
        let offsets = |b: &Bvh| b.skeleton().joints().iter().map(|j| j.offset.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        prop_assert_eq!(offsets(&back), offsets(&clip));
    }

    #[test]
    fn crlf_tabs_and_exponents_read_the_same(clip in clip()) {
        let mut text = Vec::new();
        bvh::write(&clip, &mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        // Names may hold spaces; everything else is separated by any mix of blanks.
        let windows: String = text
            .lines()
            .map(|l| {
                let named = ["ROOT", "JOINT"].iter().any(|k| l.trim_start().starts_with(k));
                let l = if named { l.to_string() } else { l.replace(' ', " \t ") };
                l + "\r\n"
            })
            .collect();
        prop_assert_eq!(bvh::read(windows.as_bytes(), ReadOptions::default()).unwrap(), clip.clone());
        // Every value spelled in scientific notation.
        let (head, rows) = text.split_at(text.find("Frame Time:").unwrap());
        let (time_line, rows) = rows.split_at(rows.find('\n').unwrap() + 1);
        let rows: String = rows
            .lines()
            .map(|l| {
                let values: Vec<String> =
                    l.split(' ').filter(|v| !v.is_empty()).map(|v| format!("{:e}", v.parse::<f32>().unwrap())).collect();
                values.join(" ") + "\n"
            })
            .collect();
        let scientific = format!("{head}{time_line}{rows}");
        let back = bvh::read(scientific.as_bytes(), ReadOptions::default()).unwrap();
        prop_assert_eq!(bits(&back), bits(&clip));
    }

    #[test]
    fn arbitrary_text_never_panics(text in ".{0,400}") {
        let _ = bvh::read(text.as_bytes(), ReadOptions::default());
    }

    #[test]
    fn damaged_files_never_panic(clip in clip(), cut in any::<prop::sample::Index>(), byte in any::<u8>()) {
        let mut text = Vec::new();
        bvh::write(&clip, &mut text).unwrap();
        let at = cut.index(text.len());
        let mut damaged = text.clone();
        damaged[at] = byte;
        let _ = bvh::read(damaged.as_slice(), ReadOptions::default());
        let _ = bvh::read(&text[..at], ReadOptions::default());
    }
}
