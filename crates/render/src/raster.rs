//! Z-buffered polygon rasterization with Lambert shading and polygon wireframes.

use glam::{DVec2, DVec3};

use crate::{Camera, Image};

/// How faces are shaded.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Shading {
    /// One normal per face (its Newell normal): facets stay visible.
    Flat,
    /// Vertex normals (area-weighted face normals) interpolated across each face.
    Smooth,
}

/// Parameters of [`render`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RenderParams {
    /// Output width in pixels. Default: `400`.
    pub width: u32,
    /// Output height in pixels. Default: `400`.
    pub height: u32,
    /// Samples per pixel along each axis (the image is rendered `k` times larger and
    /// box-filtered). Default: `2`.
    pub supersample: u32,
    /// Flat or smooth shading. Default: [`Shading::Flat`].
    pub shading: Shading,
    /// Colour of faces without a per-face colour. Default: light grey `[200, 200, 205]`.
    pub colour: [u8; 3],
    /// Background colour. Default: white.
    pub background: [u8; 3],
    /// Colour faces seen from behind are tinted towards (half way), showing folds and
    /// inverted faces; `None` shades both sides alike. Default: `Some([220, 60, 40])`.
    pub back_colour: Option<[u8; 3]>,
    /// Polygon edges drawn in this colour, or `None`. Default: `Some([40, 40, 40])`.
    pub wireframe: Option<[u8; 3]>,
    /// Wire width in output pixels. Default: `0.6`.
    pub wire_width: f64,
    /// Direction the light travels, in view coordinates (right, up, forward). Default:
    /// from the upper left, behind the viewer: `(1, -1, 2)`.
    pub light: DVec3,
    /// Ambient share of the lighting, in `[0, 1]`. Default: `0.3`.
    pub ambient: f64,
}

impl Default for RenderParams {
    fn default() -> Self {
        RenderParams {
            width: 400,
            height: 400,
            supersample: 2,
            shading: Shading::Flat,
            colour: [200, 200, 205],
            background: [255, 255, 255],
            back_colour: Some([220, 60, 40]),
            wireframe: Some([40, 40, 40]),
            wire_width: 0.6,
            light: DVec3::new(1.0, -1.0, 2.0),
            ambient: 0.3,
        }
    }
}

/// Renders polygons (`faces` index `positions`, counter-clockwise around the outward
/// normal; faces with fewer than 3 vertices or an index out of range are skipped) seen
/// by `camera`. `face_colours`, when given, has one colour per face.
///
/// Each polygon is split into a fan of triangles from its first vertex; a pixel belongs
/// to a triangle when its centre is inside (either winding), and the nearest triangle at
/// a pixel wins (ties: the first drawn). The wireframe is part of the face it bounds, so
/// hidden edges stay hidden.
pub fn render<'a>(
    positions: &[DVec3],
    faces: impl IntoIterator<Item = &'a [u32]>,
    face_colours: Option<&[[u8; 3]]>,
    camera: &Camera,
    params: &RenderParams,
) -> Image {
    let k = params.supersample.max(1);
    let (w, h) = (params.width * k, params.height * k);
    let scale = f64::from(w.min(h)) / (2.0 * camera.half_extent);
    let view: Vec<DVec3> = positions.iter().map(|&p| camera.view(p)).collect();
    let screen: Vec<DVec2> = view
        .iter()
        .map(|v| DVec2::new(0.5 * f64::from(w) + v.x * scale, 0.5 * f64::from(h) - v.y * scale))
        .collect();
    let faces: Vec<&[u32]> = faces
        .into_iter()
        .filter(|f| f.len() >= 3 && f.iter().all(|&v| (v as usize) < positions.len()))
        .collect();
    // Newell normals (unnormalized: twice the vector area), computed in the scene's
    // right-handed frame and then expressed in view coordinates (right, up, forward),
    // which are left-handed.
    let to_view = |n: DVec3| DVec3::new(n.dot(camera.right), n.dot(camera.up), n.dot(camera.forward));
    let face_normals: Vec<DVec3> = faces
        .iter()
        .map(|f| {
            to_view((0..f.len()).fold(DVec3::ZERO, |n, i| {
                n + positions[f[i] as usize].cross(positions[f[(i + 1) % f.len()] as usize])
            }))
        })
        .collect();
    let vertex_normals = (params.shading == Shading::Smooth).then(|| {
        let mut vn = vec![DVec3::ZERO; positions.len()];
        for (f, n) in faces.iter().zip(&face_normals) {
            f.iter().for_each(|&v| vn[v as usize] += *n);
        }
        vn.into_iter().map(|n| n.normalize_or_zero()).collect::<Vec<_>>()
    });
    let light = -params.light.normalize();
    let wire = params.wire_width * f64::from(k);
    let mut image = Image::new(w, h, params.background);
    let mut depth = vec![f64::INFINITY; w as usize * h as usize];
    for (fi, f) in faces.iter().enumerate() {
        let base = face_colours.and_then(|c| c.get(fi)).copied().unwrap_or(params.colour);
        let n_face = face_normals[fi].normalize_or_zero();
        let m = f.len();
        for t in 1..m - 1 {
            let tri = [f[0] as usize, f[t] as usize, f[t + 1] as usize];
            let s = tri.map(|v| screen[v]);
            let area = (s[1] - s[0]).perp_dot(s[2] - s[0]);
            if area.abs() < 1e-12 {
                continue;
            }
            // Which triangle edges are polygon edges: (v_t, v_t+1) always, and the first
            // and last fan edges. Edge i is opposite corner i.
            let boundary = [true, t == m - 2, t == 1];
            let lo = s[0].min(s[1]).min(s[2]).floor().max(DVec2::ZERO);
            let hi = s[0].max(s[1]).max(s[2]).ceil().min(DVec2::new(f64::from(w), f64::from(h)));
            let edge_len = [(s[2] - s[1]).length(), (s[0] - s[2]).length(), (s[1] - s[0]).length()];
            for py in lo.y as u32..hi.y as u32 {
                for px in lo.x as u32..hi.x as u32 {
                    let p = DVec2::new(f64::from(px) + 0.5, f64::from(py) + 0.5);
                    let b = [
                        (s[2] - s[1]).perp_dot(p - s[1]) / area,
                        (s[0] - s[2]).perp_dot(p - s[2]) / area,
                        (s[1] - s[0]).perp_dot(p - s[0]) / area,
                    ];
                    if b.iter().any(|&x| x < 0.0) {
                        continue;
                    }
                    let z = b[0] * view[tri[0]].z + b[1] * view[tri[1]].z + b[2] * view[tri[2]].z;
                    let i = py as usize * w as usize + px as usize;
                    if z >= depth[i] {
                        continue;
                    }
                    depth[i] = z;
                    let on_wire = params.wireframe.is_some()
                        && (0..3).any(|e| boundary[e] && b[e] * area.abs() / edge_len[e] < wire);
                    let colour = if on_wire {
                        params.wireframe.unwrap_or_default()
                    } else {
                        let n = match &vertex_normals {
                            Some(vn) => (b[0] * vn[tri[0]] + b[1] * vn[tri[1]] + b[2] * vn[tri[2]])
                                .normalize_or(n_face),
                            None => n_face,
                        };
                        // Seen from behind when the normal points away from the viewer.
                        let back = n_face.z > 0.0;
                        let n = if back { -n } else { n };
                        let lambert = n.dot(light).max(0.0);
                        let shade = params.ambient + (1.0 - params.ambient) * lambert;
                        let c = match (back, params.back_colour) {
                            (true, Some(bc)) => std::array::from_fn(|c| base[c] / 2 + bc[c] / 2),
                            _ => base,
                        };
                        c.map(|x| (f64::from(x) * shade).round().clamp(0.0, 255.0) as u8)
                    };
                    image.set_pixel(i64::from(px), i64::from(py), colour);
                }
            }
        }
    }
    image.downsample(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 6 outward quads of the cube `[-1, 1]^3`.
    fn cube() -> (Vec<DVec3>, Vec<[u32; 4]>) {
        let p = (0..8)
            .map(|i| {
                DVec3::new(
                    f64::from(i & 1) * 2.0 - 1.0,
                    f64::from(i >> 1 & 1) * 2.0 - 1.0,
                    f64::from(i >> 2) * 2.0 - 1.0,
                )
            })
            .collect();
        let q = vec![[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        (p, q)
    }

    fn count(img: &Image, pred: impl Fn([u8; 3]) -> bool) -> usize {
        (0..img.height())
            .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| pred(img.pixel(x, y)))
            .count()
    }

    #[test]
    fn a_cube_seen_face_on_covers_its_square() {
        let (p, q) = cube();
        // Looking down -z at the face z = 1: a square of side 2 in a view of half extent
        // 1.04 * sqrt(3) covers (2 / (2 * 1.04 * sqrt 3))^2 = 30.8% of the image.
        let camera = Camera::fit(DVec3::splat(-1.0), DVec3::ONE, DVec3::NEG_Z, DVec3::Y);
        let params = RenderParams { width: 200, height: 200, wireframe: None, ..RenderParams::default() };
        let img = render(&p, q.iter().map(|f| &f[..]), None, &camera, &params);
        let covered = count(&img, |c| c != params.background) as f64 / 40000.0;
        let expected = (1.0 / (1.04 * 3f64.sqrt())).powi(2);
        assert!((covered - expected).abs() < 0.01, "{covered} vs {expected}");
        // The front face is uniformly lit and not tinted as a back face.
        let c = img.pixel(100, 100);
        assert_eq!(c, img.pixel(80, 120));
        assert!(c[0] <= c[2] && c != params.background, "{c:?}");
    }

    #[test]
    fn the_nearest_face_wins_whatever_the_drawing_order() {
        // Two overlapping squares: red at z = 0 (near, the camera looks down -z from +z)
        // and blue at z = -1 (far).
        let p = vec![
            DVec3::new(-1., -1., 0.),
            DVec3::new(1., -1., 0.),
            DVec3::new(1., 1., 0.),
            DVec3::new(-1., 1., 0.),
            DVec3::new(-0.5, -0.5, -1.),
            DVec3::new(1.5, -0.5, -1.),
            DVec3::new(1.5, 1.5, -1.),
            DVec3::new(-0.5, 1.5, -1.),
        ];
        let faces = [[0u32, 1, 2, 3], [4, 5, 6, 7]];
        let camera = Camera::fit(DVec3::new(-1., -1., -1.), DVec3::new(1.5, 1.5, 0.), DVec3::NEG_Z, DVec3::Y);
        let params = RenderParams {
            width: 100,
            height: 100,
            wireframe: None,
            ambient: 1.0,
            ..RenderParams::default()
        };
        let colours = [[255, 0, 0], [0, 0, 255]];
        let a = render(&p, faces.iter().map(|f| &f[..]), Some(&colours), &camera, &params);
        let rev = [faces[1], faces[0]];
        let rev_colours = [colours[1], colours[0]];
        let b = render(&p, rev.iter().map(|f| &f[..]), Some(&rev_colours), &camera, &params);
        assert_eq!(a, b);
        // The overlap is red; the far square shows where the near one is absent.
        let centre = camera.view(DVec3::new(0.5, 0.5, 0.0));
        let to_px = |v: DVec3| {
            let s = 100.0 / (2.0 * camera.half_extent);
            ((50.0 + v.x * s) as u32, (50.0 - v.y * s) as u32)
        };
        let (x, y) = to_px(centre);
        assert_eq!(a.pixel(x, y), [255, 0, 0]);
        let (x, y) = to_px(camera.view(DVec3::new(1.3, 1.3, -1.0)));
        assert_eq!(a.pixel(x, y), [0, 0, 255]);
        assert!(count(&a, |c| c == [255, 0, 0]) > count(&a, |c| c == [0, 0, 255]));
    }

    #[test]
    fn wireframe_draws_polygon_edges_not_fan_diagonals() {
        let p = vec![
            DVec3::new(-1., -1., 0.),
            DVec3::new(1., -1., 0.),
            DVec3::new(1., 1., 0.),
            DVec3::new(-1., 1., 0.),
        ];
        let quad = [0u32, 1, 2, 3];
        let camera = Camera::fit(DVec3::new(-1., -1., 0.), DVec3::new(1., 1., 0.), DVec3::NEG_Z, DVec3::Y);
        let params = RenderParams {
            width: 100,
            height: 100,
            supersample: 1,
            wire_width: 1.0,
            ..RenderParams::default()
        };
        let img = render(&p, [&quad[..]], None, &camera, &params);
        let wire = params.wireframe.unwrap();
        // The diagonal from vertex 0 to 2 passes through the centre: not a wire.
        assert_ne!(img.pixel(50, 50), wire);
        assert_ne!(img.pixel(40, 60), wire);
        // The square's border is: left edge at x = 50 - 100 / (2 * 1.04 * sqrt 2) = 16.
        let left = (50.0 - 100.0 / (2.0 * 1.04 * 2f64.sqrt())) as u32;
        assert_eq!(img.pixel(left, 50), wire);
        assert!(count(&img, |c| c == wire) > 4 * 60);
    }

    #[test]
    fn back_faces_are_tinted_and_smooth_shading_varies_across_a_face() {
        let (p, q) = cube();
        let camera = Camera::fit(DVec3::splat(-1.0), DVec3::ONE, DVec3::new(-1., -0.7, -0.4), DVec3::Y);
        let params = RenderParams { width: 120, height: 120, wireframe: None, ..RenderParams::default() };
        let front = render(&p, q.iter().map(|f| &f[..]), None, &camera, &params);
        let flipped: Vec<[u32; 4]> = q.iter().map(|f| [f[0], f[3], f[2], f[1]]).collect();
        let back = render(&p, flipped.iter().map(|f| &f[..]), None, &camera, &params);
        let reddish = |c: [u8; 3]| i32::from(c[0]) > i32::from(c[2]) + 30;
        assert_eq!(count(&front, reddish), 0);
        assert!(count(&back, reddish) > 2000);
        // Flat: three face colours; smooth: many more shades.
        let distinct = |img: &Image| {
            let mut v: Vec<[u8; 3]> =
                (0..120).flat_map(|y| (0..120).map(move |x| (x, y))).map(|(x, y)| img.pixel(x, y)).collect();
            v.sort_unstable();
            v.dedup();
            v.len()
        };
        let smooth = render(
            &p,
            q.iter().map(|f| &f[..]),
            None,
            &camera,
            &RenderParams { shading: Shading::Smooth, supersample: 1, ..params },
        );
        let flat =
            render(&p, q.iter().map(|f| &f[..]), None, &camera, &RenderParams { supersample: 1, ..params });
        assert!(distinct(&flat) <= 4, "{}", distinct(&flat));
        assert!(distinct(&smooth) > 50, "{}", distinct(&smooth));
    }
}
