//! `lod-figure [--out FILE.png] [--ratio R] VOLUME...`: each volume regularized as the
//! CLI does, then simplified to a ratio of its faces with the partition kept
//! (`voxreg_simplify`, the CLI's `--simplify R`), rendered before and after, side by
//! side, one row per volume. A label volume shows the walls between its labels (faces
//! touching labels 0 and 1, the background and the tissue's skin, left out, so the inner
//! partition is seen); a `.vox` model shows its colours.

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::DVec3;
use voxreg_io::{is_voxel_art, read_volume, QuadMesh};
use voxreg_regularize::{regularize, Params};
use voxreg_render::{render, Camera, Image, RenderParams};
use voxreg_simplify::{simplify, Options, Target};

const PANEL: u32 = 520;
const CAPTION: u32 = 26;
const TEXT: [u8; 3] = [30, 30, 30];

/// A distinct colour per label pair: hues spaced by the golden angle.
fn pair_colour(l: [u32; 2]) -> [u8; 3] {
    let key = l[0].min(l[1]) * 31 + l[0].max(l[1]) * 7;
    let h = (f64::from(key) * 0.618_033_988_75).fract() * 6.0;
    let (c, x) = (0.5, 0.5 * (1.0 - (h % 2.0 - 1.0).abs()));
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    [r, g, b].map(|t| ((t + 0.4) * 255.0).round().min(255.0) as u8)
}

/// The faces drawn (distinct vertices of each) and their colours.
fn drawn(mesh: &QuadMesh, voxel_art: bool) -> (Vec<Vec<u32>>, Vec<[u8; 3]>) {
    let mut faces = Vec::new();
    let mut colours = Vec::new();
    for (f, q) in mesh.quads.iter().enumerate() {
        let l = mesh.face_labels[f];
        let colour = if voxel_art {
            match mesh.face_materials.get(f) {
                Some(&m) => {
                    let c = mesh.materials[m as usize].color;
                    [c[0], c[1], c[2]]
                }
                None => [200, 200, 205],
            }
        } else {
            if l.contains(&0) || l.contains(&1) {
                continue;
            }
            pair_colour(l)
        };
        let p: Vec<u32> = (0..4).filter(|&i| q[i] != q[(i + 3) % 4]).map(|i| q[i]).collect();
        faces.push(p);
        colours.push(colour);
    }
    (faces, colours)
}

fn panel(mesh: &QuadMesh, voxel_art: bool, camera: &Camera, caption: &str) -> Image {
    let (faces, colours) = drawn(mesh, voxel_art);
    let params = RenderParams {
        width: PANEL,
        height: PANEL,
        wireframe: Some([60, 60, 65]),
        wire_width: 0.45,
        back_colour: None,
        ..RenderParams::default()
    };
    let img = render(&mesh.positions, faces.iter().map(Vec::as_slice), Some(&colours), camera, &params);
    let mut out = Image::new(PANEL, PANEL + CAPTION, [255; 3]);
    out.draw_text_centred(PANEL as f32 / 2.0, 4.0, 15.0, TEXT, caption);
    out.blit(&img, 0, i64::from(CAPTION));
    out
}

pub(crate) fn lod_figure(args: &[String]) -> Result<()> {
    let mut out = PathBuf::from("docs/figures/simplify.png");
    let mut ratio = 0.1;
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out = PathBuf::from(it.next().context("--out needs a file")?),
            "--ratio" => ratio = it.next().context("--ratio needs a number")?.parse().context("--ratio")?,
            f => files.push(PathBuf::from(f)),
        }
    }
    anyhow::ensure!(
        !files.is_empty(),
        "usage: cargo xtask lod-figure [--out FILE.png] [--ratio R] VOLUME..."
    );
    let mut rows = Vec::new();
    for path in &files {
        let loaded = read_volume(path).with_context(|| format!("reading {}", path.display()))?;
        let voxel_art = is_voxel_art(path);
        let params = if voxel_art { Params::voxel_art() } else { Params::default() };
        let result = regularize(&loaded.volume, &params)?;
        let mut full = QuadMesh::from_surface(&result.surface, &result.positions);
        if let Some(palette) = &loaded.palette {
            full.assign_materials(palette);
        }
        let voxel = loaded.volume.spacing().min_element();
        let simple =
            simplify(&full, Target { ratio: Some(ratio), max_error: 0.5 * voxel }, &Options::default())?;
        // Framed on the faces drawn.
        let (drawn_faces, _) = drawn(&full, voxel_art);
        let (lo, hi) = drawn_faces
            .iter()
            .flatten()
            .map(|&v| full.positions[v as usize])
            .fold((DVec3::MAX, DVec3::MIN), |(lo, hi), p| (lo.min(p), hi.max(p)));
        let forward = if voxel_art { DVec3::new(-1.0, 1.2, -0.7) } else { DVec3::new(-0.25, 0.35, -1.0) };
        let up = if voxel_art { DVec3::Z } else { DVec3::Y };
        let camera = Camera::fit(lo, hi, forward.normalize(), up);
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let s = simple.stats;
        let before = panel(&full, voxel_art, &camera, &format!("{name}: {} quads", full.quads.len()));
        let after = panel(
            &simple.mesh,
            voxel_art,
            &camera,
            &format!(
                "simplified: {} faces ({:.0}% quads), {:.1}x fewer, within {:.2} voxel",
                s.faces,
                100.0 * s.quads as f64 / s.faces.max(1) as f64,
                s.input_faces as f64 / s.faces.max(1) as f64,
                s.error_bound / voxel
            ),
        );
        println!(
            "{name}: {} -> {} faces, {} quads, bound {:.3}",
            s.input_faces, s.faces, s.quads, s.error_bound
        );
        rows.push((before, after));
    }
    let mut img = Image::new(2 * PANEL, rows.len() as u32 * (PANEL + CAPTION), [255; 3]);
    for (i, (a, b)) in rows.iter().enumerate() {
        let y = i64::from(i as u32 * (PANEL + CAPTION));
        img.blit(a, 0, y);
        img.blit(b, i64::from(PANEL), y);
    }
    img.write_png(&out).with_context(|| format!("writing {}", out.display()))?;
    println!("wrote {}", out.display());
    Ok(())
}
