//! BVH channels and the rotation their Euler angles compose: a joint's rotation channels, in
//! the order listed, are `R = R1(a1) R2(a2) R3(a3)` (each about the joint's own axes after the
//! previous ones), as Biovision, MotionBuilder and Blender read them.

use std::fmt;

use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// One channel of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    pub const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The channel's name in a BVH file.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// The channel a name stands for, in any case (writers differ: `Xrotation`, `XROTATION`).
    pub fn from_name(name: &str) -> Option<Channel> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// The axis (0 for x, 1 for y, 2 for z).
    pub fn axis(self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    pub fn is_rotation(self) -> bool {
        matches!(
            self,
            Channel::Xrotation | Channel::Yrotation | Channel::Zrotation
        )
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The rotation of Euler angles (radians) applied as their channels say, e.g. `[(Zrotation, z),
/// (Yrotation, y), (Xrotation, x)]` is `Rz(z) Ry(y) Rx(x)`; position channels are skipped.
pub fn rotation_from_channels(channels: &[(Channel, f64)]) -> UnitQuaternion<f64> {
    let mut q = UnitQuaternion::identity();
    for &(channel, angle) in channels {
        let axis = match channel {
            Channel::Xrotation => Vector3::x_axis(),
            Channel::Yrotation => Vector3::y_axis(),
            Channel::Zrotation => Vector3::z_axis(),
            _ => continue,
        };
        q *= UnitQuaternion::from_axis_angle(&axis, angle);
    }
    q
}

/// The rotation `Rz(z) Ry(y) Rx(x)` of Euler angles (radians) `[z, y, x]`, the order our BVH
/// export writes.
pub fn from_euler_zyx(angles: [f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(
        angles[2], angles[1], angles[0],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rotation matrix about one axis, written out (independent of nalgebra's axis-angle).
    fn elementary(axis: usize, a: f64) -> nalgebra::Matrix3<f64> {
        let (s, c) = a.sin_cos();
        match axis {
            0 => nalgebra::Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
            1 => nalgebra::Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
            _ => nalgebra::Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
        }
    }

    #[test]
    fn every_rotation_order_composes_its_matrices_left_to_right() {
        let rotations = [Channel::Xrotation, Channel::Yrotation, Channel::Zrotation];
        let angles = [0.7, -1.1, 2.3];
        let orders = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        for order in orders {
            let channels: Vec<(Channel, f64)> = order
                .iter()
                .zip(angles)
                .map(|(&axis, a)| (rotations[axis], a))
                .collect();
            let expected = order
                .iter()
                .zip(angles)
                .fold(nalgebra::Matrix3::identity(), |m, (&axis, a)| {
                    m * elementary(axis, a)
                });
            let got = rotation_from_channels(&channels).to_rotation_matrix();
            let off = (got.matrix() - expected).abs().max();
            assert!(off < 1e-12, "order {order:?}: off by {off}");
        }
    }

    #[test]
    fn euler_zyx_is_z_then_y_then_x() {
        let angles = [0.3, -0.4, 1.9];
        let expected =
            elementary(2, angles[0]) * elementary(1, angles[1]) * elementary(0, angles[2]);
        let got = from_euler_zyx(angles).to_rotation_matrix();
        assert!((got.matrix() - expected).abs().max() < 1e-12);
    }

    #[test]
    fn channel_names_read_in_any_case() {
        assert_eq!(Channel::from_name("XROTATION"), Some(Channel::Xrotation));
        assert_eq!(Channel::from_name("yposition"), Some(Channel::Yposition));
        assert_eq!(Channel::from_name("Wrotation"), None);
    }
}
