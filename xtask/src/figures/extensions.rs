//! The papers' section 4.5 extensions: Fig. 12 (geodesics on the proxy, mapped back onto
//! the digital surface), Fig. 13 (upscaling), Fig. 14 (texture-aware fairness).

use voxreg_geodesic::{exact_distances, GeodesicMesh};
use voxreg_io::scalar_ramp;
use voxreg_upscale::{upscale, UpscaleParams};

use super::*;

/// Per-quad colours of per-vertex distances: the ramp of the quad's mean distance over
/// `largest`, darkened on the quads an iso-line crosses.
fn distance_colours(mesh: &GeodesicMesh, d: &[f64], largest: f64, spacing: f64) -> Vec<[u8; 3]> {
    let iso = mesh.iso_polygons(d, spacing);
    mesh.polygon_values(d)
        .iter()
        .zip(iso)
        .map(|(&x, line)| {
            let c = scalar_ramp(x / largest);
            if line {
                c.map(|v| (f64::from(v) * 0.3).round() as u8)
            } else {
                c
            }
        })
        .collect()
}

/// The bunny regularized with the default pipeline as one solid.
fn regularized(surface: &DigitalSurface) -> Result<Vec<DVec3>> {
    let params = Params { regions: RegionMap::single_solid(), ..Params::default() };
    Ok(Regularizer::new(surface.clone()).run(&params)?.positions.into_vec())
}

pub(super) fn fig12(index: &mut Index, path: &Path) -> Result<()> {
    let (_, surface) = load(path)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = bunny_camera(lo, hi);
    let x = regularized(&surface)?;
    let quads = quads(&surface);
    let digital = GeodesicMesh::new(input.as_slice(), &quads)?;
    let proxy = GeodesicMesh::new(&x, &quads)?;
    // The source: the vertex nearest the middle of the box's top (-y up) front.
    let source = digital
        .nearest_vertex(DVec3::new(0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z)))
        .context("empty surface")?;
    let (on_digital, _) = exact_distances(&digital, &[source])?;
    let (on_proxy, _) = exact_distances(&proxy, &[source])?;
    let largest = on_proxy.iter().chain(&on_digital).copied().filter(|d| d.is_finite()).fold(0.0, f64::max);
    let spacing = largest / 16.0;
    let shot = |caption: &str, positions: &[DVec3], mesh: &GeodesicMesh, d: &[f64]| Shot {
        caption: caption.into(),
        mesh: Mesh::from_surface(&surface, positions),
        colours: Some(distance_colours(mesh, d, largest, spacing)),
        shading: Shading::Flat,
        wireframe: false,
    };
    let images = vec![
        panel(&shot("(a) digital metric", &input, &digital, &on_digital), &camera),
        panel(&shot("(b) proxy metric, on the voxels", &input, &digital, &on_proxy), &camera),
        panel(&shot("(c) proxy metric, on the proxy", &x, &proxy, &on_proxy), &camera),
    ];
    let name = file_name(path);
    let img = grid(&format!("Fig. 12: exact geodesics on {name}"), &[(String::new(), images)]);
    index.add_png(
        "fig12_geodesics.png",
        "Fig. 12: geodesics on the digital surface and on the regularized proxy",
        format!(
            "{name}, exact polyhedral geodesic distance from one vertex (improved Chen-Han), iso-lines every \
             {spacing:.1} voxels (dark quads), ramp dark red (0) to light grey. (a) measured on the staircase: \
             the iso-lines are squarish, the metric anisotropic; (b) measured on the regularized surface and \
             mapped back onto the same quads; (c) on the regularized surface itself. \
             <code>voxreg geodesic INPUT --from X,Y,Z [--metric digital] [--on digital] -o OUT.ply</code> \
             writes the same distances."
        ),
        &img,
    )
}

pub(super) fn fig13(index: &mut Index, path: &Path, factors: &[usize]) -> Result<()> {
    let (loaded, surface) = load(path)?;
    let x = regularized(&surface)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = bunny_camera(lo, hi);
    let mut images = vec![panel(&Shot::new("input", Mesh::from_surface(&surface, &input)), &camera)];
    let mut sizes = Vec::new();
    for &factor in factors {
        let fine = upscale(&surface, &x, &loaded.volume, &UpscaleParams { factor })?;
        let d = fine.dims();
        sizes.push(format!("{}x{}x{}", d[0], d[1], d[2]));
        let fine_surface = DigitalSurface::new(&fine, &RegionMap::single_solid())?;
        drop(fine);
        let positions = fine_surface.positions();
        let mut shot = Shot::new(
            format!("x{factor}: {}^3", d[0].max(d[1]).max(d[2])),
            Mesh::from_surface(&fine_surface, &positions),
        );
        shot.wireframe = false;
        images.push(panel(&shot, &camera));
    }
    let name = file_name(path);
    let img = grid(&format!("Fig. 13: upscaling {name}"), &[(String::new(), images)]);
    index.add_png(
        "fig13_upscaling.png",
        "Fig. 13: upscaling",
        format!(
            "{name} regularized (default pipeline), then voxelized at {} (<code>voxreg upscale -k K</code>): \
             the finer staircases follow the smooth surface.",
            sizes.join(" and ")
        ),
        &img,
    )
}

pub(super) fn fig14(index: &mut Index, path: &Path) -> Result<()> {
    let (loaded, surface) = load(path)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = Camera::fit(lo, hi, DVec3::new(-0.6, 0.75, -0.3), DVec3::Z);
    let mut qm = QuadMesh::from_surface(&surface, &input);
    let palette = loaded.palette.as_ref().context("a coloured input")?;
    qm.assign_materials(palette);
    let colours: Vec<[u8; 3]> = qm
        .face_materials
        .iter()
        .map(|&m| {
            let c = qm.materials[m as usize].color;
            [c[0], c[1], c[2]]
        })
        .collect();
    let mut images = Vec::new();
    for (caption, texture_aware) in [("fairness", false), ("texture-aware fairness", true)] {
        // Unclamped, so the fairness term is what places the quads.
        let params = Params { regions: RegionMap::single_solid(), texture_aware, ..Params::papers() };
        let x = Regularizer::new(surface.clone()).run(&params)?.positions.into_vec();
        let shot = Shot {
            caption: caption.into(),
            mesh: Mesh::from_surface(&surface, &x),
            colours: Some(colours.clone()),
            shading: Shading::Flat,
            wireframe: true,
        };
        images.push(panel(&shot, &camera));
    }
    let name = file_name(path);
    let img = grid(&format!("Fig. 14: texture-aware fairness on {name}"), &[(String::new(), images)]);
    index.add_png(
        "fig14_texture_aware.png",
        "Fig. 14: texture-aware fairness",
        format!(
            "{name} as one solid, the papers' weights, without and with texture-aware fairness \
             (<code>--texture-aware</code>): with it, the barycenters leave out the neighbours across a colour \
             boundary, so quad edges follow the colour boundaries."
        ),
        &img,
    )
}
