//! A fixed orthographic camera.

use glam::DVec3;

/// An orthographic camera: a view direction, an up vector, and the region of space that
/// fills the image.
///
/// Screen coordinates: `x` along [`Camera::right`], `y` along [`Camera::up`], depth along
/// the view direction (smaller is nearer).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Camera {
    /// The point at the image centre.
    pub centre: DVec3,
    /// Unit direction the camera looks along.
    pub forward: DVec3,
    /// Unit screen-right direction.
    pub right: DVec3,
    /// Unit screen-up direction.
    pub up: DVec3,
    /// Half the width (and height) of the square region of the view plane shown by the
    /// shorter image side, in scene units.
    pub half_extent: f64,
}

impl Camera {
    /// Frames the box `[min, max]` seen along `forward` with `up` upwards on screen: the
    /// box's bounding sphere fits the image with a 4% margin, whatever the direction.
    /// `up` must not be parallel to `forward`.
    pub fn fit(min: DVec3, max: DVec3, forward: DVec3, up: DVec3) -> Camera {
        let forward = forward.normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        let radius = 0.5 * (max - min).length();
        Camera { centre: 0.5 * (min + max), forward, right, up, half_extent: 1.04 * radius.max(1e-12) }
    }

    /// `p` in view coordinates: right, up, depth (all relative to the centre).
    pub fn view(&self, p: DVec3) -> DVec3 {
        let d = p - self.centre;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }
}
