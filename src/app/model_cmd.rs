//! `mrsmap model info|render`: what a model file holds, in words and as a picture.

use super::render::{View, render};
use crate::io::image::write_rgb8;
use crate::io::tum::format_stamp;
use crate::model::{FORMAT_VERSION, Model, load};
use crate::slam::VolumeShape;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::Path;

/// A description of a model file.
pub fn info(path: &Path) -> Result<String> {
    let size = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?.len();
    let model = load(path)?;
    Ok(describe(&model, size))
}

/// The description of a loaded model (`size` is the file's length in bytes).
pub fn describe(model: &Model, size: u64) -> String {
    let h = &model.header;
    let mut s = String::new();
    let _ = writeln!(s, "model '{}' (format version {FORMAT_VERSION}, {:.1} KiB)", h.name, size as f64 / 1024.0);
    let _ = writeln!(s, "  frame            {}", h.frame);
    let [tx, ty, tz, qx, qy, qz, qw] = h.world_from_model;
    let _ = writeln!(
        s,
        "  world_from_model t = [{tx:.4}, {ty:.4}, {tz:.4}] m, q = [{qx:.4}, {qy:.4}, {qz:.4}, {qw:.4}] (x y z w)"
    );
    let src = &h.source;
    let _ = writeln!(s, "  source           {} (camera {})", src.dataset, src.camera);
    let _ = writeln!(
        s,
        "                   {} frames, {} .. {}, {} key views; {}",
        src.frames,
        format_stamp(src.first_stamp_ns),
        format_stamp(src.last_stamp_ns),
        src.key_views,
        src.created_by
    );
    let p = h.map_params.params();
    let _ = writeln!(
        s,
        "  resolution       {} levels, finest {:.4} m, coarsest {:.3} m, λ = {}",
        p.num_levels,
        p.finest_resolution_m,
        p.resolution(p.num_levels - 1),
        p.lambda
    );
    match &h.volume {
        Some(v) => {
            let _ = writeln!(s, "  volume           {}", describe_shape(&v.shape));
        }
        None => {
            let _ = writeln!(s, "  volume           none (whole scene)");
        }
    }
    let r = &h.root;
    let std = [r.covariance[0], r.covariance[3], r.covariance[5]].map(|v| v.max(0.0).sqrt());
    let _ = writeln!(
        s,
        "  root statistics  {:.0} points, mean [{:.3}, {:.3}, {:.3}] m, std [{:.3}, {:.3}, {:.3}] m",
        r.count, r.mean[0], r.mean[1], r.mean[2], std[0], std[1], std[2]
    );
    let _ = writeln!(s, "  storage          {} nodes, {} surfels", h.nodes, h.surfels);
    let per_level = model.map.usable_surfels_per_level();
    let _ = writeln!(s, "  usable surfels   per level, finest first:");
    for (level, n) in per_level.iter().enumerate().take(p.num_levels) {
        let _ = writeln!(s, "                   {:.4} m: {n}", p.resolution(level));
    }
    s
}

fn describe_shape(shape: &VolumeShape) -> String {
    match shape {
        VolumeShape::Prism { polygon, min_z, max_z } => {
            format!("prism of {} corners on the support plane, heights {min_z:.3}..{max_z:.3} m", polygon.len())
        }
        VolumeShape::Box { half_extents } => {
            format!("box, half extents [{:.3}, {:.3}, {:.3}] m", half_extents[0], half_extents[1], half_extents[2])
        }
    }
}

/// Renders a model file to a PNG; returns the number of surfels drawn.
pub fn render_file(path: &Path, out: &Path, view: &View) -> Result<usize> {
    let model = load(path)?;
    let picture = render(&model.map, view);
    write_rgb8(out, picture.width, picture.height, &picture.rgb)?;
    Ok(picture.drawn)
}
