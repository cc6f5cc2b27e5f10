//! Frames in types at module boundaries: a position or direction that
//! crosses a module says its frame in its type, so that a NED vector passed
//! where a body vector is expected does not compile. Inside a module the
//! plain nalgebra math stays ([`Point::vector`], or deref).
//!
//! Frames (ARCHITECTURE.md section 3): [`Camera`] (OpenCV: x right, y down,
//! z forward), [`BodyFrd`] (x forward, y right, z down), [`LocalNed`] (the
//! autopilot's local north-east-down). Quaternions are Hamilton, w first in
//! every file and message: [`quaternion_from_wxyz`] and
//! [`quaternion_to_wxyz`] are the one pair of conversions.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::marker::PhantomData;
use std::ops::{Add, Deref, Sub};

/// The camera frame (OpenCV optical axes), metres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Camera;
/// The receiver's body frame, FRD, metres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BodyFrd;
/// The autopilot's local NED frame (origin at its EKF origin), metres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LocalNed;

/// A position in frame `F`, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point<F> {
    metres: Vector3<f64>,
    frame: PhantomData<F>,
}

impl<F> Point<F> {
    /// The point at `metres` (coordinates in frame `F`).
    pub fn new(metres: Vector3<f64>) -> Self {
        Self {
            metres,
            frame: PhantomData,
        }
    }

    /// The point at `[x, y, z]` metres in frame `F`.
    pub fn from_array(metres: [f64; 3]) -> Self {
        Self::new(Vector3::from(metres))
    }

    /// The coordinates, for the math inside a module.
    pub fn vector(&self) -> &Vector3<f64> {
        &self.metres
    }

    /// The coordinates `[x, y, z]`, metres, for file formats and messages.
    pub fn to_array(&self) -> [f64; 3] {
        self.metres.into()
    }
}

impl<F> Deref for Point<F> {
    type Target = Vector3<f64>;
    fn deref(&self) -> &Vector3<f64> {
        &self.metres
    }
}

/// A point moved by an offset in its own frame is a point of that frame.
impl<F> Add<Vector3<f64>> for Point<F> {
    type Output = Point<F>;
    fn add(self, offset: Vector3<f64>) -> Point<F> {
        Point::new(self.metres + offset)
    }
}

/// The offset between two points of one frame (points of two frames do
/// not subtract).
impl<F> Sub for Point<F> {
    type Output = Vector3<f64>;
    fn sub(self, other: Point<F>) -> Vector3<f64> {
        self.metres - other.metres
    }
}

/// A unit direction in frame `F`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Direction<F> {
    unit: Vector3<f64>,
    frame: PhantomData<F>,
}

impl<F> Direction<F> {
    /// `v` as a direction; the caller gives a unit vector (the measurement's
    /// normals are unit by construction).
    pub fn new(v: Vector3<f64>) -> Self {
        Self {
            unit: v,
            frame: PhantomData,
        }
    }

    /// The unit vector, for the math inside a module.
    pub fn vector(&self) -> &Vector3<f64> {
        &self.unit
    }

    /// The components `[x, y, z]`, for file formats and messages.
    pub fn to_array(&self) -> [f64; 3] {
        self.unit.into()
    }
}

impl<F> Deref for Direction<F> {
    type Target = Vector3<f64>;
    fn deref(&self) -> &Vector3<f64> {
        &self.unit
    }
}

/// A Hamilton quaternion written w first (files, MAVLink, Foxglove, the
/// simulator's truth) as a rotation; `None` when it is not finite or has no
/// length.
pub fn quaternion_from_wxyz(q: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    (q.coords.iter().all(|c| c.is_finite()) && q.norm() > 1e-9)
        .then(|| UnitQuaternion::from_quaternion(q))
}

/// A rotation as a Hamilton quaternion written w first.
pub fn quaternion_to_wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_round_trip_w_first() {
        // 90 degrees about z: w = cos 45, k = sin 45 (Hamilton, w first).
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let wxyz = quaternion_to_wxyz(&q);
        for (a, b) in wxyz.iter().zip([h, 0.0, 0.0, h]) {
            assert!((a - b).abs() < 1e-12, "{wxyz:?}");
        }
        let back = quaternion_from_wxyz(wxyz).unwrap();
        assert!(back.angle_to(&q) < 1e-12);
        // x axis turns into y.
        assert!((back * Vector3::x() - Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn bad_quaternions_are_refused() {
        assert!(quaternion_from_wxyz([0.0; 4]).is_none());
        assert!(quaternion_from_wxyz([f64::NAN, 0.0, 0.0, 1.0]).is_none());
        assert!(quaternion_from_wxyz([f64::INFINITY, 0.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn points_keep_their_coordinates() {
        let p: Point<BodyFrd> = Point::from_array([1.0, -2.0, 3.0]);
        assert_eq!(p.to_array(), [1.0, -2.0, 3.0]);
        assert_eq!(p.norm(), 14f64.sqrt());
    }
}
