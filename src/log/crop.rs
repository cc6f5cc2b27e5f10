//! The crop-and-decimate log mode (`[log] image_encoding = "crop"`): on
//! every frame a lossless crop around the drogue goes to `/camera/crop`
//! (PNG, `foxglove.CompressedImage`), with where it lies in the frame on
//! `/camera/crop_info` (JSON); full frames go to `/camera/image` only every
//! `full_frame_every`-th frame.
//!
//! The crop is centred on the frame's detected ellipse, scaled from the inner
//! circle to the canopy (`[drogue]` canopy/inner radius) and by
//! `crop_margin`, and mapped into the distorted image the frame is in. A
//! frame without a detection is cropped around the last detection of the
//! last [`HOLD_NS`] (the drogue moves little in that time; the tracker's own
//! prediction is not published by the measurement); with none, it gets no
//! crop. The frame arrives before its measurement, so frames wait here
//! (at most [`MAX_PENDING`]) until the measurement of their sequence number
//! or a later one comes.

use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::measure::ellipse::Ellipse;
use serde::Serialize;
use std::collections::VecDeque;
use std::sync::Arc;

/// How long a detection still places the crops of undetected frames, ns.
pub const HOLD_NS: u64 = 1_000_000_000;
/// Frames waiting for their measurement; an older one is cropped around the
/// last detection when more arrive (a measurement that never comes).
pub const MAX_PENDING: usize = 8;
/// Points sampled on the scaled ellipse for its distorted bounding box.
const SAMPLES: usize = 72;

/// Where a crop lies in its frame, pixels (`/camera/crop_info`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct CropRect {
    /// Top-left pixel of the crop in the frame.
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// What a crop was placed around.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CropBasis {
    /// This frame's detection.
    Detection,
    /// The last detection (within [`HOLD_NS`]): this frame had none, or was
    /// not measured.
    LastDetection,
}

/// The crop around `ellipse` (inner circle, undistorted pixels) grown by
/// `scale` (canopy/inner ratio times the margin), as the bounding box of the
/// scaled ellipse in the distorted image, clipped to the frame. None when
/// it misses the frame or the ellipse is not finite.
pub fn crop_rect(ellipse: &Ellipse, scale: f64, camera: &CameraModel) -> Option<CropRect> {
    let grown = Ellipse {
        a: ellipse.a * scale,
        b: ellipse.b * scale,
        ..*ellipse
    };
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let centre = [ellipse.cx, ellipse.cy];
    for i in 0..=SAMPLES {
        let p = if i == SAMPLES {
            centre
        } else {
            grown.point_at(std::f64::consts::TAU * i as f64 / SAMPLES as f64)
        };
        let [u, v] = camera.distort_px(p);
        if !(u.is_finite() && v.is_finite()) {
            return None;
        }
        (x0, y0, x1, y1) = (x0.min(u), y0.min(v), x1.max(u), y1.max(v));
    }
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    // Whole pixels that the box touches, clipped to the frame.
    let (x0, y0) = (x0.floor().max(0.0), y0.floor().max(0.0));
    let (x1, y1) = ((x1.ceil() + 1.0).min(w), (y1.ceil() + 1.0).min(h));
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    Some(CropRect {
        x: x0 as u32,
        y: y0 as u32,
        width: (x1 - x0) as u32,
        height: (y1 - y0) as u32,
    })
}

/// The pixels of `rect` of `frame`, row-major.
pub fn crop_pixels(frame: &Frame, rect: &CropRect, out: &mut Vec<u8>) {
    out.clear();
    let width = frame.image.width() as usize;
    let raw = frame.image.as_raw();
    for row in rect.y..rect.y + rect.height {
        let start = row as usize * width + rect.x as usize;
        out.extend_from_slice(&raw[start..start + rect.width as usize]);
    }
}

/// A frame to crop, and where.
pub struct Crop {
    pub frame: Arc<Frame>,
    pub rect: CropRect,
    pub basis: CropBasis,
}

/// Frames waiting for their measurement, and the last detection.
pub struct Cropper {
    scale: f64,
    camera: CameraModel,
    pending: VecDeque<Arc<Frame>>,
    /// The last detected ellipse and its frame's capture time.
    last: Option<(Ellipse, u64)>,
}

impl Cropper {
    /// `scale`: canopy/inner radius ratio times the margin.
    pub fn new(scale: f64, camera: CameraModel) -> Self {
        Self {
            scale,
            camera,
            pending: VecDeque::new(),
            last: None,
        }
    }

    /// A new frame: waits for its measurement. Returns the crops of frames
    /// pushed out of the wait.
    pub fn frame(&mut self, frame: Arc<Frame>) -> Vec<Crop> {
        self.pending.push_back(frame);
        let mut out = Vec::new();
        while self.pending.len() > MAX_PENDING {
            if let Some(f) = self.pending.pop_front() {
                out.extend(self.around_last(f));
            }
        }
        out
    }

    /// The measurement of frame `seq` (with its ellipse when detected): that
    /// frame's crop, and those of older frames never measured.
    pub fn measurement(
        &mut self,
        seq: u64,
        capture_time_ns: u64,
        ellipse: Option<&Ellipse>,
    ) -> Vec<Crop> {
        let mut out = Vec::new();
        while self.pending.front().is_some_and(|f| f.seq < seq) {
            if let Some(f) = self.pending.pop_front() {
                out.extend(self.around_last(f));
            }
        }
        if let Some(e) = ellipse {
            self.last = Some((*e, capture_time_ns));
        }
        if self.pending.front().is_some_and(|f| f.seq == seq)
            && let Some(f) = self.pending.pop_front()
        {
            match ellipse {
                Some(e) => out.extend(self.around(f, e, CropBasis::Detection)),
                None => out.extend(self.around_last(f)),
            }
        }
        out
    }

    /// Every waiting frame (at the end of the log).
    pub fn drain(&mut self) -> Vec<Crop> {
        let frames: Vec<_> = self.pending.drain(..).collect();
        frames
            .into_iter()
            .filter_map(|f| self.around_last(f))
            .collect()
    }

    fn around_last(&self, frame: Arc<Frame>) -> Option<Crop> {
        let (e, t) = self.last?;
        if frame.capture_time_ns.abs_diff(t) > HOLD_NS {
            return None;
        }
        self.around(frame, &e, CropBasis::LastDetection)
    }

    fn around(&self, frame: Arc<Frame>, e: &Ellipse, basis: CropBasis) -> Option<Crop> {
        let rect = crop_rect(e, self.scale, &self.camera)?;
        Some(Crop { frame, rect, basis })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    fn camera(distortion: [f64; 5]) -> CameraModel {
        let k = Matrix3::new(1000.0, 0.0, 640.0, 0.0, 1000.0, 480.0, 0.0, 0.0, 1.0);
        CameraModel::new("t", 1280, 960, k, distortion).unwrap()
    }

    #[test]
    fn crop_is_the_scaled_ellipse_box_without_distortion() {
        // A circle of radius 10 px at (100.5, 200.5), scaled 3x: 30 px.
        let e = Ellipse::new(100.5, 200.5, 10.0, 10.0, 0.0);
        let r = crop_rect(&e, 3.0, &camera([0.0; 5])).unwrap();
        assert_eq!((r.x, r.y), (70, 170));
        assert_eq!((r.width, r.height), (62, 62));
    }

    #[test]
    fn crop_is_clipped_to_the_frame_and_none_outside() {
        let cam = camera([0.0; 5]);
        let r = crop_rect(&Ellipse::new(5.0, 950.0, 20.0, 10.0, 0.3), 2.0, &cam).unwrap();
        assert_eq!(r.x, 0);
        assert!(r.y < 950 - 20, "{r:?}");
        assert_eq!(r.y + r.height, 960);
        assert!(crop_rect(&Ellipse::new(-500.0, 100.0, 20.0, 20.0, 0.0), 2.0, &cam).is_none());
        assert!(crop_rect(&Ellipse::new(f64::NAN, 100.0, 20.0, 20.0, 0.0), 2.0, &cam).is_none());
    }

    fn frame(seq: u64) -> Arc<Frame> {
        Arc::new(Frame {
            seq,
            capture_time_ns: seq * 100_000_000,
            image: image::GrayImage::new(1280, 960),
            origin: crate::frame::FrameOrigin::Camera {
                device: "test".into(),
            },
        })
    }

    fn seqs(crops: &[Crop]) -> Vec<(u64, CropBasis)> {
        crops.iter().map(|c| (c.frame.seq, c.basis)).collect()
    }

    /// Frames wait for their measurement; an undetected or unmeasured frame
    /// is cropped around the last detection within HOLD_NS, else not at all.
    #[test]
    fn frames_are_cropped_when_measured_around_the_detection_or_the_last_one() {
        let e = Ellipse::new(640.0, 480.0, 20.0, 18.0, 0.0);
        let mut c = Cropper::new(2.0, camera([0.0; 5]));
        assert!(c.frame(frame(0)).is_empty());
        // Nothing detected yet: no crop.
        assert!(c.measurement(0, 0, None).is_empty());
        c.frame(frame(1));
        c.frame(frame(2));
        let crops = c.measurement(1, 100_000_000, Some(&e));
        assert_eq!(seqs(&crops), [(1, CropBasis::Detection)]);
        // Frame 2 was never measured: cropped around frame 1's detection
        // when frame 3's (undetected) measurement comes.
        c.frame(frame(3));
        let crops = c.measurement(3, 300_000_000, None);
        let expected = [(2, CropBasis::LastDetection), (3, CropBasis::LastDetection)];
        assert_eq!(seqs(&crops), expected);
        // More than a second after the last detection: no crop.
        c.frame(frame(15));
        assert!(c.measurement(15, 1_500_000_000, None).is_empty());
        // The wait is bounded; the rest comes out at the end.
        c.measurement(16, 1_600_000_000, Some(&e));
        let pushed: Vec<Crop> = (17..17 + MAX_PENDING as u64 + 2)
            .flat_map(|s| c.frame(frame(s)))
            .collect();
        assert_eq!(pushed.len(), 2);
        assert_eq!(c.drain().len(), MAX_PENDING);
    }

    #[test]
    fn distorted_ring_points_lie_in_the_crop() {
        let cam = camera([-0.2, 0.05, 0.001, -0.001, 0.0]);
        let e = Ellipse::new(1000.0, 800.0, 40.0, 25.0, 0.7);
        let r = crop_rect(&e, 2.2, &cam).unwrap();
        for i in 0..360 {
            let t = f64::from(i).to_radians();
            let grown = Ellipse {
                a: e.a * 2.2,
                b: e.b * 2.2,
                ..e
            };
            let [u, v] = cam.distort_px(grown.point_at(t));
            assert!(
                u >= f64::from(r.x) && u < f64::from(r.x + r.width),
                "u {u} {r:?}"
            );
            assert!(
                v >= f64::from(r.y) && v < f64::from(r.y + r.height),
                "v {v} {r:?}"
            );
        }
    }
}
