//! The topics of the log (ARCHITECTURE.md section 7) and how each message is
//! built: Foxglove protobuf messages, and JSON for our own records.

use super::ImageEncoding;
use super::png_gray::GrayPngEncoder;
use crate::camera::CameraModel;
use crate::frame::Frame;
use crate::measure::mount::Mount;
use crate::measure::{Detection, Measurement};
use crate::spatial::{Direction, Point, quaternion_to_wxyz};
use foxglove::messages::{
    CameraCalibration, CircleAnnotation, Color, CompressedImage, FrameTransform, FrameTransforms,
    ImageAnnotations, Log, Point2, PointsAnnotation, Pose, PoseInFrame, Quaternion, RawImage,
    TextAnnotation, Timestamp, Vector3 as FgVector3, points_annotation,
};
use foxglove::{Encode, Schema};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The camera frames (PNG, JPEG or raw mono8; in crop mode every `full_frame_every`-th).
pub const IMAGE: &str = "/camera/image";
/// The camera's calibration, with every frame.
pub const CALIBRATION: &str = "/camera/calibration";
/// `image_encoding = "crop"`: the PNG crop around the drogue, every frame.
pub const CROP: &str = "/camera/crop";
/// JSON: where each `/camera/crop` lies in its frame (`super::crop`).
pub const CROP_INFO: &str = "/camera/crop_info";
/// Image annotations: the fitted ellipse, the rim points and the inliers.
pub const ANNOTATIONS: &str = "/drogue/annotations";
/// JSON: the per-frame record (`DetectionRecord`), every measured frame.
pub const DETECTION: &str = "/drogue/detection";
/// The drogue's pose in the camera frame, when detected.
pub const POSE: &str = "/drogue/pose";
/// Transforms body → camera, body → probe and camera → drogue.
pub const TF: &str = "/tf";
/// JSON: every MAVLink message sent.
pub const MAVLINK_OUT: &str = "/mavlink/out";
/// JSON: every MAVLink message received (within its own budget).
pub const MAVLINK_IN: &str = "/mavlink/in";
/// JSON: the simulator's `FrameTruth`, simulated frames only.
pub const SIM_TRUTH: &str = "/sim/truth";
/// Every tracing event of the run.
pub const LOG: &str = "/log";
/// JSON: the run's resource figures (CPU, memory, queue depths), every second.
pub const STATS: &str = "/drogue/stats";

/// frame_id of the camera frame (image, calibration, pose, transforms).
pub const CAMERA_FRAME: &str = "camera";
/// frame_id of the receiver's body frame (FRD).
pub const BODY_FRAME: &str = "body";
/// frame_id of the drogue frame (origin at the disc's centre, z along its normal).
pub const DROGUE_FRAME: &str = "drogue";
/// frame_id of the probe tip.
pub const PROBE_FRAME: &str = "probe";

/// A channel's schema and message encoding.
pub struct ChannelSpec {
    /// The message schema (protobuf descriptor or JSON schema).
    pub schema: Schema,
    /// The messages' encoding (`protobuf` or `json`).
    pub message_encoding: &'static str,
}

fn proto<T: Encode>() -> Result<ChannelSpec, String> {
    let schema = T::get_schema().ok_or("a foxglove message type without a schema")?;
    Ok(ChannelSpec {
        schema,
        message_encoding: "protobuf",
    })
}

/// JSON messages with a permissive JSON schema (Foxglove wants one).
fn json(name: &str) -> ChannelSpec {
    ChannelSpec {
        schema: Schema::new(name, "jsonschema", br#"{"type":"object"}"#.to_vec()),
        message_encoding: "json",
    }
}

/// The channel spec of `topic` (the image topic's depends on the encoding).
pub fn channel_spec(topic: &str, image: ImageEncoding) -> Result<ChannelSpec, String> {
    match topic {
        IMAGE if !image.is_compressed() => proto::<RawImage>(),
        IMAGE | CROP => proto::<CompressedImage>(),
        CROP_INFO => Ok(json("drogue_vision.CropInfo")),
        CALIBRATION => proto::<CameraCalibration>(),
        ANNOTATIONS => proto::<ImageAnnotations>(),
        POSE => proto::<PoseInFrame>(),
        TF => proto::<FrameTransforms>(),
        LOG => proto::<Log>(),
        DETECTION => Ok(json("drogue_vision.Detection")),
        MAVLINK_OUT | MAVLINK_IN => Ok(json("drogue_vision.MavlinkMessage")),
        SIM_TRUTH => Ok(json("drogue_vision.SimTruth")),
        STATS => Ok(json("drogue_vision.RunStats")),
        other => Err(format!("unknown topic {other}")),
    }
}

/// Protobuf bytes of a Foxglove message.
pub fn encode<T: Encode>(msg: &T, buf: &mut Vec<u8>) -> Result<(), String> {
    buf.clear();
    if let Some(n) = msg.encoded_len() {
        buf.reserve(n);
    }
    msg.encode(buf).map_err(|e| e.to_string())
}

/// A protobuf timestamp of Unix-epoch nanoseconds (saturating after 2106).
pub fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (ns % 1_000_000_000) as u32)
}

/// `/camera/image`: the frame (`png` reuses the buffers of `png`; the crop
/// mode's full frames are PNG; JPEG at `jpeg_quality`).
pub fn image(
    frame: &Frame,
    encoding: ImageEncoding,
    jpeg_quality: u8,
    png: &mut GrayPngEncoder,
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    let (width, height) = frame.image.dimensions();
    let ts = Some(timestamp(frame.capture_time_ns));
    match encoding {
        ImageEncoding::Raw => encode(
            &RawImage {
                timestamp: ts,
                frame_id: CAMERA_FRAME.into(),
                width,
                height,
                encoding: "mono8".into(),
                step: width,
                data: frame.image.as_raw().clone().into(),
            },
            buf,
        ),
        ImageEncoding::Png | ImageEncoding::Crop => {
            let mut data = Vec::new();
            png.encode(frame.image.as_raw(), width, height, &mut data)?;
            compressed(frame.capture_time_ns, data, "png", buf)
        }
        ImageEncoding::Jpeg => {
            let mut data = Vec::new();
            jpeg(frame.image.as_raw(), width, height, jpeg_quality, &mut data)?;
            compressed(frame.capture_time_ns, data, "jpeg", buf)
        }
    }
}

/// A `foxglove.CompressedImage` in the camera frame.
pub fn compressed(
    time_ns: u64,
    data: Vec<u8>,
    format: &str,
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    encode(
        &CompressedImage {
            timestamp: Some(timestamp(time_ns)),
            frame_id: CAMERA_FRAME.into(),
            data: data.into(),
            format: format.into(),
        },
        buf,
    )
}

/// Baseline JPEG of 8-bit gray pixels, with the `jpeg-encoder` crate (AVX2
/// where the CPU has it): the `image` crate's encoder could not hold 30 fps
/// of 1280x960 on the log's thread (39 of 600 frames dropped in a 20 s run).
pub fn jpeg(
    pixels: &[u8],
    width: u32,
    height: u32,
    quality: u8,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    out.clear();
    let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
        return Err(format!(
            "JPEG: {width}x{height} is over 65535 pixels wide or high"
        ));
    };
    jpeg_encoder::Encoder::new(&mut *out, quality)
        .encode(pixels, w, h, jpeg_encoder::ColorType::Luma)
        .map_err(|e| format!("JPEG: {e}"))
}

/// `/camera/calibration` of the camera model (ROS camera_info conventions).
pub fn calibration(camera: &CameraModel, time_ns: u64) -> CameraCalibration {
    CameraCalibration {
        timestamp: Some(timestamp(time_ns)),
        frame_id: CAMERA_FRAME.into(),
        width: camera.width,
        height: camera.height,
        distortion_model: "plumb_bob".into(),
        d: camera.distortion.to_vec(),
        k: camera.k_row_major().to_vec(),
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: camera.projection_row_major().to_vec(),
    }
}

/// The camera model back from a `/camera/calibration` message.
pub fn camera_from_calibration(c: &CameraCalibration) -> Result<CameraModel, String> {
    if c.k.len() != 9 {
        return Err(format!("calibration K has {} values, not 9", c.k.len()));
    }
    let mut distortion = [0.0; 5];
    if c.d.len() > 5 || (!c.d.is_empty() && c.distortion_model != "plumb_bob") {
        return Err(format!(
            "unsupported distortion {:?} with {} coefficients",
            c.distortion_model,
            c.d.len()
        ));
    }
    distortion[..c.d.len()].copy_from_slice(&c.d);
    let k = Matrix3::from_row_slice(&c.k);
    CameraModel::new(CAMERA_FRAME, c.width, c.height, k, distortion)
}

/// The camera mount as plain transforms, for `/tf`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MountTransforms {
    /// Camera origin in body FRD, metres.
    pub camera_in_body_m: [f64; 3],
    /// Rotation camera → body, Hamilton, w first.
    pub q_body_camera: [f64; 4],
    /// Probe tip in body FRD, metres.
    pub probe_in_body_m: [f64; 3],
}

impl MountTransforms {
    /// Read off a [`Mount`] through its point/vector mappings (so it follows
    /// whatever the mount implements).
    pub fn from_mount(mount: &Mount) -> Self {
        let camera_in_body_m = mount.point_camera_to_body(&Point::new(Vector3::zeros()));
        let axis = |v: Vector3<f64>| *mount.vector_camera_to_body(&Direction::new(v)).vector();
        let r_body_camera =
            Matrix3::from_columns(&[axis(Vector3::x()), axis(Vector3::y()), axis(Vector3::z())]);
        let q = UnitQuaternion::from_matrix(&r_body_camera);
        // point_body_from_probe(p) = p - probe tip.
        let probe_in_body_m = -mount
            .point_body_from_probe(&Point::new(Vector3::zeros()))
            .vector();
        Self {
            camera_in_body_m: camera_in_body_m.to_array(),
            q_body_camera: quaternion_to_wxyz(&q),
            probe_in_body_m: probe_in_body_m.into(),
        }
    }
}

/// Orientation of the drogue frame in the camera frame: z = the drogue normal
/// (toward the camera); x, y span the drogue plane (x as close to camera x as
/// the plane allows, so it is stable from frame to frame).
pub fn q_camera_drogue(normal_camera: &Vector3<f64>) -> UnitQuaternion<f64> {
    let z = normal_camera.normalize();
    let reference = if z.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x = (reference - z * z.dot(&reference)).normalize();
    let y = z.cross(&x);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, z]))
}

fn fg_vec(v: &Vector3<f64>) -> FgVector3 {
    FgVector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

fn fg_quat(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

/// `/drogue/pose`: the chosen circle pose in the camera frame.
pub fn pose(d: &Detection, time_ns: u64) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(time_ns)),
        frame_id: CAMERA_FRAME.into(),
        pose: Some(Pose {
            position: Some(fg_vec(&d.pose_camera.centre_camera_m)),
            orientation: Some(fg_quat(&q_camera_drogue(&d.pose_camera.normal_camera))),
        }),
    }
}

/// `/tf`: body→camera and body→probe every frame, camera→drogue when detected.
pub fn transforms(m: &Measurement, mount: &MountTransforms) -> FrameTransforms {
    let ts = Some(timestamp(m.capture_time_ns));
    let [w, x, y, z] = mount.q_body_camera;
    let mut transforms = vec![
        FrameTransform {
            timestamp: ts,
            parent_frame_id: BODY_FRAME.into(),
            child_frame_id: CAMERA_FRAME.into(),
            translation: Some(fg_vec(&mount.camera_in_body_m.into())),
            rotation: Some(Quaternion { x, y, z, w }),
        },
        FrameTransform {
            timestamp: ts,
            parent_frame_id: BODY_FRAME.into(),
            child_frame_id: PROBE_FRAME.into(),
            translation: Some(fg_vec(&mount.probe_in_body_m.into())),
            rotation: Some(fg_quat(&UnitQuaternion::identity())),
        },
    ];
    if let Some(d) = &m.detection {
        transforms.push(FrameTransform {
            timestamp: ts,
            parent_frame_id: CAMERA_FRAME.into(),
            child_frame_id: DROGUE_FRAME.into(),
            translation: Some(fg_vec(&d.pose_camera.centre_camera_m)),
            rotation: Some(fg_quat(&q_camera_drogue(&d.pose_camera.normal_camera))),
        });
    }
    FrameTransforms { transforms }
}

const GREEN: Color = Color {
    r: 0.1,
    g: 0.9,
    b: 0.2,
    a: 1.0,
};
const RED: Color = Color {
    r: 1.0,
    g: 0.2,
    b: 0.1,
    a: 1.0,
};
const CYAN: Color = Color {
    r: 0.0,
    g: 0.9,
    b: 1.0,
    a: 1.0,
};
const YELLOW: Color = Color {
    r: 1.0,
    g: 0.9,
    b: 0.0,
    a: 1.0,
};
const WHITE: Color = Color {
    r: 1.0,
    g: 1.0,
    b: 1.0,
    a: 1.0,
};
const SHADE: Color = Color {
    r: 0.0,
    g: 0.0,
    b: 0.0,
    a: 0.6,
};

/// Points drawn along the fitted ellipse.
const ELLIPSE_SAMPLES: usize = 72;

/// Foxglove puts image coordinate (0, 0) at the top-left CORNER of the image;
/// ours (OpenCV) at the top-left pixel's centre: shift by half a pixel.
fn fg_point(p_px: [f64; 2]) -> Point2 {
    Point2 {
        x: p_px[0] + 0.5,
        y: p_px[1] + 0.5,
    }
}

/// `/drogue/annotations`: rim points (inliers green, outliers red), the fitted
/// ellipse (cyan, drawn in the distorted image), the projected circle centre
/// (yellow) and a caption. Published every frame so stale drawings clear.
pub fn annotations(m: &Measurement, camera: &CameraModel) -> ImageAnnotations {
    let ts = Some(timestamp(m.capture_time_ns));
    let mut out = ImageAnnotations {
        timestamp: ts,
        ..Default::default()
    };
    let caption = match &m.detection {
        None => "no drogue".to_string(),
        Some(d) => {
            out.points.push(PointsAnnotation {
                timestamp: ts,
                r#type: points_annotation::Type::Points as i32,
                points: d
                    .rim_points_px
                    .iter()
                    .map(|p| fg_point([f64::from(p[0]), f64::from(p[1])]))
                    .collect(),
                outline_colors: (0..d.rim_points_px.len())
                    .map(|i| {
                        if d.inliers.get(i).copied().unwrap_or(false) {
                            GREEN
                        } else {
                            RED
                        }
                    })
                    .collect(),
                thickness: 3.0,
                ..Default::default()
            });
            out.points.push(PointsAnnotation {
                timestamp: ts,
                r#type: points_annotation::Type::LineLoop as i32,
                points: (0..ELLIPSE_SAMPLES)
                    .map(|i| {
                        let t = std::f64::consts::TAU * i as f64 / ELLIPSE_SAMPLES as f64;
                        fg_point(camera.distort_px(d.ellipse_px.point_at(t)))
                    })
                    .collect(),
                outline_color: Some(CYAN),
                thickness: 2.0,
                ..Default::default()
            });
            if let Some(c) = camera.project_px(&d.pose_camera.centre_camera_m) {
                out.circles.push(CircleAnnotation {
                    timestamp: ts,
                    position: Some(fg_point(c)),
                    diameter: 8.0,
                    thickness: 2.0,
                    fill_color: Some(YELLOW),
                    outline_color: Some(YELLOW),
                    ..Default::default()
                });
            }
            format!(
                "range {:.2} m  inliers {}/{}  rms {:.2} px",
                d.pose_camera.centre_camera_m.norm(),
                d.quality.inliers,
                d.quality.points,
                d.quality.rms_residual_px
            )
        }
    };
    out.texts.push(TextAnnotation {
        timestamp: ts,
        position: Some(Point2 { x: 10.0, y: 30.0 }),
        text: format!("#{} {caption}", m.seq),
        font_size: 24.0,
        text_color: Some(WHITE),
        background_color: Some(SHADE),
        ..Default::default()
    });
    out
}

/// `/log` message of one event.
pub(crate) fn log_message(e: &super::LogEvent) -> Log {
    Log {
        timestamp: Some(timestamp(e.time_ns)),
        level: e.level as i32,
        message: e.message.clone(),
        name: e.name.clone(),
        file: e.file.clone(),
        line: e.line,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drogue_frame_z_is_the_normal() {
        for n in [
            Vector3::new(0.0, 0.0, -1.0),
            Vector3::new(0.3, -0.2, -0.9).normalize(),
            Vector3::new(-1.0, 0.0, 0.0),
        ] {
            let q = q_camera_drogue(&n);
            let z = q * Vector3::z();
            assert!((z - n).norm() < 1e-12, "{z} vs {n}");
        }
    }

    #[test]
    fn timestamps_split_nanoseconds() {
        let t = timestamp(1_700_000_000_123_456_789);
        assert_eq!((t.sec(), t.nsec()), (1_700_000_000, 123_456_789));
    }

    #[test]
    fn calibration_round_trips_the_camera() {
        let cam = crate::testing::paper_camera([0.1, -0.2, 0.001, 0.002, 0.03]);
        let back = camera_from_calibration(&calibration(&cam, 5)).unwrap();
        assert_eq!(back.k, cam.k);
        assert_eq!(back.distortion, cam.distortion);
        assert_eq!((back.width, back.height), (1280, 960));
    }
}
