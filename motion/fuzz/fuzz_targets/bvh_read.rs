//! Any bytes: the BVH reader returns a value or an error, never panics; whatever it accepts
//! writes back to text that reads to the same value, and decodes to a motion that encodes.
#![no_main]

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::motion::Motion;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(clip) = bvh::read(data, ReadOptions::default()) {
        let mut text = Vec::new();
        bvh::write(&clip, &mut text).expect("writing to memory");
        let again = bvh::read(text.as_slice(), ReadOptions::default()).expect("written BVH reads back");
        assert_eq!(again, clip);
        let motion = Motion::from_bvh(&clip);
        let _ = motion.to_bvh();
    }
});
