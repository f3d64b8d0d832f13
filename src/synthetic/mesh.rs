//! Triangle meshes with per-vertex colours or a texture.

use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use nalgebra::{Point3, Vector3};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a mesh could not be loaded.
#[derive(Debug, Error)]
pub enum MeshError {
    /// A file could not be read.
    #[error("cannot read {path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        message: String,
    },
    /// A line of an OBJ file is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// An RGB texture.
#[derive(Debug, Clone)]
pub struct Texture {
    /// Width (px).
    pub width: usize,
    /// Height (px).
    pub height: usize,
    /// RGB8 pixels, row-major, first row at the top (v = 1).
    pub rgb: Vec<u8>,
}

/// A triangle mesh in metres.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vector3<f64>>,
    /// Per-vertex colours (used without a texture).
    pub colors: Vec<[u8; 3]>,
    /// Per-corner texture coordinates, parallel to `triangles` (used with a texture).
    pub uvs: Vec<[[f32; 2]; 3]>,
    /// Vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// Optional texture.
    pub texture: Option<Texture>,
}

impl Mesh {
    /// Colour at barycentric coordinates of triangle `i`.
    pub fn color_at(&self, i: usize, bary: [f64; 3]) -> [u8; 3] {
        let tri = &self.triangles[i];
        if let Some(tex) = &self.texture {
            let uv = self.uvs[i];
            let u = bary[0] * uv[0][0] as f64 + bary[1] * uv[1][0] as f64 + bary[2] * uv[2][0] as f64;
            let v = bary[0] * uv[0][1] as f64 + bary[1] * uv[1][1] as f64 + bary[2] * uv[2][1] as f64;
            let x = ((u.rem_euclid(1.0)) * tex.width as f64).floor().clamp(0.0, (tex.width - 1) as f64) as usize;
            let y =
                ((1.0 - v.rem_euclid(1.0)) * tex.height as f64).floor().clamp(0.0, (tex.height - 1) as f64) as usize;
            let k = 3 * (y * tex.width + x);
            return [tex.rgb[k], tex.rgb[k + 1], tex.rgb[k + 2]];
        }
        let mut c = [0.0f64; 3];
        for (k, b) in bary.iter().enumerate() {
            let col = self.colors[tri[k] as usize];
            for ch in 0..3 {
                c[ch] += b * col[ch] as f64;
            }
        }
        c.map(|v| v.round().clamp(0.0, 255.0) as u8)
    }

    /// Transforms every vertex.
    pub fn transform(&mut self, pose: &Pose) {
        for p in &mut self.positions {
            *p = (pose * Point3::from(*p)).coords;
        }
    }

    /// Appends another mesh.
    pub fn append(&mut self, other: &Mesh) {
        assert!(self.texture.is_none() && other.texture.is_none(), "append needs vertex-coloured meshes");
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.colors.extend_from_slice(&other.colors);
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }

    /// A surface mesh of an RGB-D frame in its camera frame: one vertex per valid
    /// pixel, two triangles per 2×2 block whose depths differ by less than
    /// `max_jump_ratio` (no triangles across depth discontinuities).
    pub fn from_frame(frame: &RgbdFrame, max_jump_ratio: f64) -> Mesh {
        let (w, h) = (frame.width(), frame.height());
        let cam = frame.camera;
        let mut mesh = Mesh::default();
        let mut index = vec![u32::MAX; w * h];
        for v in 0..h {
            for u in 0..w {
                let d = frame.depth[v * w + u];
                if d == 0 {
                    continue;
                }
                let Some((x, y)) = cam.unproject_normalized(u as f64, v as f64) else { continue };
                let z = d as f64 * cam.depth_scale_m;
                index[v * w + u] = mesh.positions.len() as u32;
                mesh.positions.push(Vector3::new(x * z, y * z, z));
                let k = 3 * (v * w + u);
                mesh.colors.push([frame.rgb[k], frame.rgb[k + 1], frame.rgb[k + 2]]);
            }
        }
        let ok = |a: u32, b: u32, m: &Mesh| {
            let (za, zb) = (m.positions[a as usize].z, m.positions[b as usize].z);
            za.min(zb) / za.max(zb) > max_jump_ratio
        };
        for v in 0..h - 1 {
            for u in 0..w - 1 {
                let (a, b, c, d) =
                    (index[v * w + u], index[v * w + u + 1], index[(v + 1) * w + u], index[(v + 1) * w + u + 1]);
                if a != u32::MAX
                    && b != u32::MAX
                    && c != u32::MAX
                    && ok(a, b, &mesh)
                    && ok(a, c, &mesh)
                    && ok(b, c, &mesh)
                {
                    mesh.triangles.push([a, c, b]);
                }
                if b != u32::MAX
                    && c != u32::MAX
                    && d != u32::MAX
                    && ok(b, d, &mesh)
                    && ok(c, d, &mesh)
                    && ok(b, c, &mesh)
                {
                    mesh.triangles.push([b, c, d]);
                }
            }
        }
        mesh
    }

    /// Scales every vertex about the origin.
    pub fn scale(&mut self, factor: f64) {
        for p in &mut self.positions {
            *p *= factor;
        }
    }

    /// Loads a Wavefront OBJ with `v`, `vt` and triangular or polygonal `f` records; the
    /// texture named by `map_Kd` in the material library is loaded if it is a PNG or a
    /// JPEG (one texture per mesh: the first `map_Kd`).
    pub fn load_obj(path: &Path) -> Result<Mesh, MeshError> {
        let io = |p: &Path, e: String| MeshError::Io { path: p.to_path_buf(), message: e };
        let text = std::fs::read_to_string(path).map_err(|e| io(path, e.to_string()))?;
        let mut mesh = Mesh::default();
        let mut uv_list: Vec<[f32; 2]> = Vec::new();
        let mut mtllib = None;
        for (i, line) in text.lines().enumerate() {
            let perr = |m: String| MeshError::Parse { path: path.to_path_buf(), line: i + 1, message: m };
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let c: Vec<f64> = it
                        .take(3)
                        .map(|x| x.parse().map_err(|_| perr(format!("bad vertex {line:?}"))))
                        .collect::<Result<_, _>>()?;
                    if c.len() != 3 {
                        return Err(perr("vertex needs 3 coordinates".into()));
                    }
                    mesh.positions.push(Vector3::new(c[0], c[1], c[2]));
                    mesh.colors.push([180, 180, 180]);
                }
                Some("vt") => {
                    let c: Vec<f32> = it
                        .take(2)
                        .map(|x| x.parse().map_err(|_| perr(format!("bad uv {line:?}"))))
                        .collect::<Result<_, _>>()?;
                    uv_list.push([c[0], *c.get(1).unwrap_or(&0.0)]);
                }
                Some("f") => {
                    let corners: Vec<(u32, Option<u32>)> = it
                        .map(|c| {
                            let mut parts = c.split('/');
                            let v: i64 =
                                parts.next().unwrap_or("").parse().map_err(|_| perr(format!("bad face {line:?}")))?;
                            let vt: Option<i64> = parts.next().and_then(|t| t.parse().ok());
                            let fix = |k: i64, n: usize| if k < 0 { (n as i64 + k) as u32 } else { (k - 1) as u32 };
                            Ok((fix(v, mesh.positions.len()), vt.map(|t| fix(t, uv_list.len()))))
                        })
                        .collect::<Result<_, MeshError>>()?;
                    for k in 1..corners.len().saturating_sub(1) {
                        let tri = [corners[0], corners[k], corners[k + 1]];
                        if tri.iter().any(|c| c.0 as usize >= mesh.positions.len()) {
                            return Err(perr("face refers to a missing vertex".into()));
                        }
                        mesh.triangles.push([tri[0].0, tri[1].0, tri[2].0]);
                        mesh.uvs.push(
                            tri.map(|c| c.1.and_then(|t| uv_list.get(t as usize).copied()).unwrap_or([0.0, 0.0])),
                        );
                    }
                }
                Some("mtllib") => mtllib = it.next().map(str::to_string),
                _ => {}
            }
        }
        if let Some(lib) = mtllib {
            let dir = path.parent().unwrap_or(Path::new("."));
            if let Ok(mtl) = std::fs::read_to_string(dir.join(&lib))
                && let Some(tex) = mtl.lines().find_map(|l| {
                    // `map_Kd [options] file`: the file is the last word.
                    l.trim().strip_prefix("map_Kd").and_then(|s| s.split_whitespace().last()).map(str::to_string)
                })
            {
                let lower = tex.to_lowercase();
                if lower.ends_with(".png") {
                    mesh.texture = Some(load_png_texture(&dir.join(tex))?);
                } else if lower.ends_with(".jpg") || lower.ends_with(".jpeg") {
                    mesh.texture = Some(load_jpeg_texture(&dir.join(tex))?);
                }
            }
        }
        Ok(mesh)
    }
}

fn load_jpeg_texture(path: &Path) -> Result<Texture, MeshError> {
    let io = |e: String| MeshError::Io { path: path.to_path_buf(), message: e };
    let bytes = std::fs::read(path).map_err(|e| io(e.to_string()))?;
    let mut rgb = Vec::new();
    let image = crate::io::compressed_image::jpeg_into(&bytes, &mut rgb).map_err(io)?;
    Ok(Texture { width: image.width, height: image.height, rgb })
}

fn load_png_texture(path: &Path) -> Result<Texture, MeshError> {
    let io = |e: String| MeshError::Io { path: path.to_path_buf(), message: e };
    let file = std::fs::File::open(path).map_err(|e| io(e.to_string()))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(|e| io(e.to_string()))?;
    let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| io("too large".into()))?];
    let info = reader.next_frame(&mut buf).map_err(|e| io(e.to_string()))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = info.color_type.samples();
    let mut rgb = Vec::with_capacity(3 * w * h);
    for px in buf[..w * h * channels].chunks_exact(channels) {
        match channels {
            1 | 2 => rgb.extend_from_slice(&[px[0], px[0], px[0]]),
            _ => rgb.extend_from_slice(&px[..3]),
        }
    }
    Ok(Texture { width: w, height: h, rgb })
}
