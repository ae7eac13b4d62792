//! The conventions a foreign export writes a 6-DoF probe's orientation in: three Euler angles about moving
//! (intrinsic) or fixed (extrinsic) axes, or a quaternion with its scalar first or last. A column mapping names one
//! (`[orientation] convention`, [`super::mapping`]).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// A parsed orientation convention.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Convention {
    /// `R = R_a(θ1)·R_b(θ2)·R_c(θ3)`, axes 0–2.
    Intrinsic([usize; 3]),
    /// `R = R_c(θ3)·R_b(θ2)·R_a(θ1)`.
    Extrinsic([usize; 3]),
    QuaternionWxyz,
    QuaternionXyzw,
}

impl Convention {
    pub fn parse(text: &str) -> std::result::Result<Convention, String> {
        let t = text.trim().to_ascii_lowercase();
        let bad = || {
            format!(
                "orientation convention '{text}': use intrinsic-ABC or extrinsic-ABC (A, B, C each x, y or z, \
                 no axis twice in a row, e.g. intrinsic-xyz, extrinsic-zyx, intrinsic-zyz), quaternion-wxyz or \
                 quaternion-xyzw"
            )
        };
        match t.as_str() {
            "quaternion-wxyz" => return Ok(Convention::QuaternionWxyz),
            "quaternion-xyzw" => return Ok(Convention::QuaternionXyzw),
            _ => {}
        }
        let (kind, axes) = t.split_once('-').ok_or_else(bad)?;
        let axes: Vec<usize> = axes
            .chars()
            .map(|c| match c {
                'x' => Some(0),
                'y' => Some(1),
                'z' => Some(2),
                _ => None,
            })
            .collect::<Option<Vec<_>>>()
            .ok_or_else(bad)?;
        let axes: [usize; 3] = axes.try_into().map_err(|_| bad())?;
        if axes[0] == axes[1] || axes[1] == axes[2] {
            return Err(bad());
        }
        match kind {
            "intrinsic" => Ok(Convention::Intrinsic(axes)),
            "extrinsic" => Ok(Convention::Extrinsic(axes)),
            _ => Err(bad()),
        }
    }

    /// Number of columns: 3 angles or 4 quaternion components.
    pub fn columns(self) -> usize {
        match self {
            Convention::Intrinsic(_) | Convention::Extrinsic(_) => 3,
            _ => 4,
        }
    }

    /// The rotation of three angles (rad) or four quaternion components; `None` for a quaternion whose norm
    /// is more than 1e-2 from 1.
    pub fn rotation(self, v: &[f64]) -> Option<UnitQuaternion<f64>> {
        let about = |axis: usize, angle: f64| {
            UnitQuaternion::from_axis_angle(
                &nalgebra::Unit::new_unchecked(Vector3::ith(axis, 1.0)),
                angle,
            )
        };
        let quaternion = |w: f64, x: f64, y: f64, z: f64| {
            let q = Quaternion::new(w, x, y, z);
            ((q.norm() - 1.0).abs() <= 1e-2).then(|| UnitQuaternion::from_quaternion(q))
        };
        match self {
            Convention::Intrinsic([a, b, c]) => {
                Some(about(a, v[0]) * about(b, v[1]) * about(c, v[2]))
            }
            Convention::Extrinsic([a, b, c]) => {
                Some(about(c, v[2]) * about(b, v[1]) * about(a, v[0]))
            }
            Convention::QuaternionWxyz => quaternion(v[0], v[1], v[2], v[3]),
            Convention::QuaternionXyzw => quaternion(v[3], v[0], v[1], v[2]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conventions() {
        let v = [0.3, -0.2, 0.5];
        let (x, y, z) = (Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis());
        let r = |a: &nalgebra::Unit<Vector3<f64>>, t: f64| UnitQuaternion::from_axis_angle(a, t);
        let intr = Convention::parse("intrinsic-xyz")
            .unwrap()
            .rotation(&v)
            .unwrap();
        assert!(intr.angle_to(&(r(&x, v[0]) * r(&y, v[1]) * r(&z, v[2]))) < 1e-15);
        let extr = Convention::parse("Extrinsic-XYZ")
            .unwrap()
            .rotation(&v)
            .unwrap();
        // nalgebra's roll-pitch-yaw is extrinsic x-y-z.
        assert!(extr.angle_to(&UnitQuaternion::from_euler_angles(v[0], v[1], v[2])) < 1e-15);
        let zyz = Convention::parse("intrinsic-zyz")
            .unwrap()
            .rotation(&v)
            .unwrap();
        assert!(zyz.angle_to(&(r(&z, v[0]) * r(&y, v[1]) * r(&z, v[2]))) < 1e-15);
        let q = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let c = q.coords; // i, j, k, w
        let wxyz = Convention::QuaternionWxyz
            .rotation(&[c[3], c[0], c[1], c[2]])
            .unwrap();
        let xyzw = Convention::QuaternionXyzw
            .rotation(&[c[0], c[1], c[2], c[3]])
            .unwrap();
        assert!(wxyz.angle_to(&q) < 1e-15 && xyzw.angle_to(&q) < 1e-15);
        assert!(
            Convention::QuaternionWxyz
                .rotation(&[2.0, 0.0, 0.0, 0.0])
                .is_none()
        );
        for bad in [
            "intrinsic-xxz",
            "xyz",
            "intrinsic-xy",
            "sideways-xyz",
            "quaternion",
        ] {
            assert!(Convention::parse(bad).is_err(), "{bad}");
        }
    }
}
