//! Camera-file parser and `build_camera_info` on arbitrary bytes: never a panic, and a camera
//! description it accepts has finite intrinsics, positive focal lengths, a rotation for the IMU,
//! the event file's sensor size and a finite IMU time offset. The event file is a stand-in
//! decoder (with or without an IMU stream, as the knob says).
#![no_main]

mod common;

use evseg_formats::{Chunk, DecodeError, DecodeStats, EventDecoder, Format, build_camera_info};
use libfuzzer_sys::fuzz_target;

/// An event file of 346 x 260 pixels without calibration.
struct StandIn {
    imu: bool,
}

impl EventDecoder for StandIn {
    fn decode_into(&mut self, _out: &mut Chunk, _max_events: usize) -> Result<bool, DecodeError> {
        Ok(false)
    }
    fn geometry(&self) -> (u16, u16) {
        (346, 260)
    }
    fn time_origin_us(&self) -> Option<i64> {
        Some(1_589_163_147_368_868)
    }
    fn format(&self) -> Format {
        Format::Aedat4
    }
    fn stats(&self) -> DecodeStats {
        DecodeStats::default()
    }
    fn has_imu(&self) -> bool {
        self.imu
    }
}

fuzz_target!(|data: &[u8]| {
    let knob = common::knob(data);
    let Some(path) = common::write_input("camera.json", data) else {
        return;
    };
    let decoder = StandIn { imu: knob & 1 != 0 };
    if let Ok(camera) = build_camera_info(&decoder, Some(&path)) {
        for v in [
            camera.fx,
            camera.fy,
            camera.cx,
            camera.cy,
            camera.imu_time_offset_s,
        ] {
            assert!(v.is_finite(), "accepted a non-finite value: {camera:?}");
        }
        assert!(
            camera.fx > 0.0 && camera.fy > 0.0,
            "accepted focal lengths {camera:?}"
        );
        assert_eq!((camera.width, camera.height), (346, 260));
        assert_eq!(camera.time_origin_us, 1_589_163_147_368_868);
        let r = camera.imu_to_camera;
        let det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6])
            + r[2] * (r[3] * r[7] - r[4] * r[6]);
        assert!((det - 1.0).abs() < 1e-2, "accepted a non-rotation {r:?}");
    }
});
