//! Rotation conversions: Euler angles (any of the six orders, degrees) <-> quaternion <->
//! matrix <-> rot6D (Zhou et al. 2019), and the geodesic angle between two rotations.

use crate::skeleton::EulerOrder;
use glam::{DQuat, Mat3, Quat, Vec3};

/// The rotation of Euler angles in degrees, composed intrinsically in `order`
/// (`angles[0]` about the first axis of the order).
pub fn euler_to_quat(order: EulerOrder, angles_deg: [f32; 3]) -> Quat {
    let [a, b, c] = angles_deg.map(|d| (d as f64).to_radians());
    DQuat::from_euler(order.glam(), a, b, c).as_quat()
}

/// Euler angles in degrees for `order` that give back `q` (the first and last angle in
/// (-180, 180], the middle one in [-90, 90] for these Tait-Bryan orders).
pub fn quat_to_euler(order: EulerOrder, q: Quat) -> [f32; 3] {
    let (a, b, c) = q.as_dquat().normalize().to_euler(order.glam());
    [a, b, c].map(|r| r.to_degrees() as f32)
}

/// The first two columns of the rotation matrix, the continuous 6D representation.
pub fn quat_to_rot6d(q: Quat) -> [f32; 6] {
    let m = Mat3::from_quat(q);
    let (a, b) = (m.x_axis, m.y_axis);
    [a.x, a.y, a.z, b.x, b.y, b.z]
}

/// The rotation nearest to a (possibly unnormalised) 6D vector, by Gram-Schmidt.
/// A degenerate input (both columns zero or parallel) maps to the identity.
pub fn rot6d_to_quat(r: [f32; 6]) -> Quat {
    let a = Vec3::new(r[0], r[1], r[2]);
    let b = Vec3::new(r[3], r[4], r[5]);
    let x = a.normalize_or_zero();
    if x == Vec3::ZERO {
        return Quat::IDENTITY;
    }
    let y = (b - x * x.dot(b)).normalize_or_zero();
    if y == Vec3::ZERO {
        return Quat::IDENTITY;
    }
    let z = x.cross(y);
    Quat::from_mat3(&Mat3::from_cols(x, y, z)).normalize()
}

/// The angle in radians of the rotation taking `a` to `b` (0..=pi), the geodesic distance on SO(3).
pub fn geodesic_angle(a: Quat, b: Quat) -> f32 {
    let d = (a.conjugate() * b).normalize();
    2.0 * d.xyz().length().atan2(d.w.abs())
}

/// Splits `q` into a rotation about `axis` (the twist) and the rest: `q = twist * swing`
/// with `swing` carrying no rotation about `axis` seen from the world.
pub fn twist_about(q: Quat, axis: Vec3) -> Quat {
    let projected = axis * q.xyz().dot(axis);
    let twist = Quat::from_xyzw(projected.x, projected.y, projected.z, q.w);
    if twist.length_squared() < 1e-12 { Quat::IDENTITY } else { twist.normalize() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::Axis;
    use proptest::prelude::*;

    fn axis_rotation(axis: Axis, deg: f32) -> Quat {
        Quat::from_axis_angle(axis.unit(), deg.to_radians())
    }

    #[test]
    fn euler_orders_compose_intrinsically_in_channel_order() {
        // ZXY = Rz * Rx * Ry: the BVH convention (channels in file order, intrinsic).
        let angles = [30.0, -50.0, 75.0];
        for order in EulerOrder::ALL {
            let [a, b, c] = order.axes();
            let expected = axis_rotation(a, angles[0]) * axis_rotation(b, angles[1]) * axis_rotation(c, angles[2]);
            let got = euler_to_quat(order, angles);
            assert!(geodesic_angle(expected, got) < 1e-5, "{order}");
        }
    }

    #[test]
    fn a_quarter_turn_about_z_maps_x_to_y() {
        let q = euler_to_quat(EulerOrder::Zxy, [90.0, 0.0, 0.0]);
        assert!((q * Vec3::X - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn geodesic_angle_of_known_rotations() {
        let a = axis_rotation(Axis::Y, 10.0);
        let b = axis_rotation(Axis::Y, 100.0);
        assert!((geodesic_angle(a, b).to_degrees() - 90.0).abs() < 1e-4);
        // q and -q are the same rotation.
        assert!(geodesic_angle(a, -a) < 1e-6);
    }

    #[test]
    fn twist_about_y_keeps_the_heading() {
        let heading = axis_rotation(Axis::Y, 40.0);
        let tilt = axis_rotation(Axis::X, 25.0);
        let twist = twist_about(heading * tilt, Vec3::Y);
        // A tilt about X leaves the yaw of the forward axis unchanged.
        let f = (heading * tilt) * Vec3::Z;
        let yaw = f.x.atan2(f.z).to_degrees();
        let t = twist * Vec3::Z;
        assert!((t.x.atan2(t.z).to_degrees() - yaw).abs() < 1e-3);
    }

    proptest! {
        #[test]
        fn euler_round_trips_for_every_order(a in -179.0f32..179.0, b in -89.0f32..89.0, c in -179.0f32..179.0) {
            for order in EulerOrder::ALL {
                let q = euler_to_quat(order, [a, b, c]);
                let back = quat_to_euler(order, q);
                for (x, y) in [a, b, c].iter().zip(back) {
                    prop_assert!((x - y).abs() < 1e-3, "{order}: {:?} -> {:?}", [a, b, c], back);
                }
            }
        }

        #[test]
        fn rot6d_and_matrix_round_trip(x in -1.0f32..1.0, y in -1.0f32..1.0, z in -1.0f32..1.0, w in -1.0f32..1.0) {
            let q = Quat::from_xyzw(x, y, z, w);
            prop_assume!(q.length() > 0.1);
            let q = q.normalize();
            prop_assert!(geodesic_angle(q, rot6d_to_quat(quat_to_rot6d(q))) < 1e-3);
            prop_assert!(geodesic_angle(q, Quat::from_mat3(&Mat3::from_quat(q))) < 1e-3);
        }
    }
}
