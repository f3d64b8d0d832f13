//! Registration of rendered scenes with exactly known motion (seeded, repeatable).

mod common;

use common::*;
use mrsmap::geometry::Pose;
use mrsmap::geometry::se3::left_increment;
use mrsmap::map::MapCapacity;
use mrsmap::map::stats::packed_index;
use mrsmap::registration::{RegistrationError, RegistrationParams, RegistrationWorkspace, register};
use mrsmap::synthetic::{Pcg32, room};
use nalgebra::Vector6;

/// A random camera motion of about `t_m` translation and `r_rad` rotation.
fn random_motion(rng: &mut Pcg32, t_m: f64, r_rad: f64) -> Pose {
    let mut d = Vector6::zeros();
    for k in 0..3 {
        d[k] = rng.uniform(-t_m, t_m);
        d[3 + k] = rng.uniform(-r_rad, r_rad);
    }
    left_increment(&d)
}

fn register_pair(
    motion: &Pose,
    seed: u64,
    camera: mrsmap::geometry::CameraModel,
) -> Result<(f64, f64, usize), RegistrationError> {
    register_pair_with(motion, seed, camera, &RegistrationParams::default())
}

fn register_pair_with(
    motion: &Pose,
    seed: u64,
    camera: mrsmap::geometry::CameraModel,
    params: &RegistrationParams,
) -> Result<(f64, f64, usize), RegistrationError> {
    let mesh = room(seed);
    let a = render_frame(&mesh, camera, &Pose::identity());
    let b = render_frame(&mesh, camera, motion);
    let (model, scene) = (build_map(&a), build_map(&b));
    let mut ws = RegistrationWorkspace::new(MapCapacity::for_image((camera.width * camera.height) as usize).nodes);
    let r = register(&model, &scene, &Pose::identity(), params, &mut ws)?;
    // The scene camera is at `motion` in the model camera's frame: model_from_scene = motion.
    let (t, deg) = pose_error(&r.model_from_scene, motion);
    Ok((t, deg, r.associations))
}

/// A map without the colour rows of the scatter (`MapParams::color_scatter` off, as in
/// odometry and tracking) has the same surfels, bit for bit, as the map with them; only
/// its colour rows are zero.
#[test]
fn maps_without_colour_scatter_have_the_same_surfels() {
    use mrsmap::map::MapParams;
    let frame = render_frame(&room(3), vga(), &Pose::identity());
    let full = build_map_with(&frame, MapParams { color_scatter: true, ..MapParams::default() });
    let position = build_map_with(&frame, MapParams { color_scatter: false, ..MapParams::default() });
    assert!(full.surfels().iter().filter(|s| s.usable()).count() > 500);
    assert_eq!(full.surfels(), position.surfels());
    assert_eq!(full.normals(), position.normals());
    assert_eq!(full.descriptors(), position.descriptors());
    // The packed scatter's position block: (i, j) with i ≤ j < 3.
    let position_block: Vec<usize> = (0..3).flat_map(|i| (i..3).map(move |j| packed_index(i, j))).collect();
    for (f, p) in full.stats().iter().zip(position.stats()) {
        assert_eq!((f.count, f.sum), (p.count, p.sum));
        for (k, (a, b)) in f.scatter.iter().zip(&p.scatter).enumerate() {
            let expected = if position_block.contains(&k) { *a } else { 0.0 };
            assert_eq!(b.to_bits(), expected.to_bits(), "scatter entry {k}");
        }
    }
    let colour = full.stats().iter().filter(|s| s.count >= 10.0 && s.color_covariance().norm() > 0.0).count();
    assert!(colour > 500, "the full map has colour scatter ({colour} surfels)");
}

#[test]
fn recovers_small_random_motions_at_vga() {
    let mut rng = Pcg32::new(7);
    for seed in 0..5 {
        let motion = random_motion(&mut rng, 0.02, 0.02);
        let (t, deg, n) = register_pair(&motion, seed, vga()).expect("registration succeeds");
        println!("seed {seed}: error {:.3} mm {:.4} deg ({n} associations)", t * 1e3, deg);
        assert!(t < 1.0e-3 && deg < 0.05, "seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
    }
}

#[test]
fn converges_without_the_confirming_fresh_pass() {
    // The tracker may stop LM on a small step without re-searching every association
    // from scratch first: on exact data the result must be as good.
    let params = RegistrationParams { confirm_with_fresh_associations: false, ..RegistrationParams::default() };
    let mut rng = Pcg32::new(7);
    for seed in 0..3 {
        let motion = random_motion(&mut rng, 0.02, 0.02);
        let (t, deg, _) = register_pair_with(&motion, seed, vga(), &params).expect("registration succeeds");
        println!("seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
        assert!(t < 1.0e-3 && deg < 0.05, "seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
    }
}

#[test]
fn recovers_larger_motions() {
    let mut rng = Pcg32::new(11);
    for seed in 0..3 {
        let motion = random_motion(&mut rng, 0.05, 0.05);
        let (t, deg, _) = register_pair(&motion, seed, vga()).expect("registration succeeds");
        println!("seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
        assert!(t < 1.5e-3 && deg < 0.08, "seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
    }
}

#[test]
fn recovers_motion_at_qvga() {
    let mut rng = Pcg32::new(3);
    for seed in 0..3 {
        let motion = random_motion(&mut rng, 0.02, 0.02);
        let (t, deg, _) = register_pair(&motion, seed, vga().halved()).expect("registration succeeds");
        println!("seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
        assert!(t < 1.0e-3 && deg < 0.05, "seed {seed}: error {:.3} mm {:.4} deg", t * 1e3, deg);
    }
}

#[test]
fn views_that_do_not_overlap_fail() {
    // The second camera is turned away from the scene by 120°: no common surface.
    let motion = left_increment(&Vector6::new(0.0, 0.0, 0.0, 0.0, 2.1, 0.0));
    let r = register_pair(&motion, 1, vga());
    println!("{r:?}");
    assert!(matches!(r, Err(RegistrationError::TooFewAssociations { .. })), "{r:?}");
}

#[test]
fn a_plain_plane_does_not_constrain_the_pose() {
    use mrsmap::synthetic::Mesh;
    use mrsmap::synthetic::scene::{ColorField, add_quad};
    use nalgebra::Vector3;
    // A uniformly grey wall: sliding along it and turning about its normal are free.
    let mut mesh = Mesh::default();
    let grey = ColorField::new(&mut Pcg32::new(1), 0);
    add_quad(
        &mut mesh,
        Vector3::new(-2.0, -2.0, 1.0),
        Vector3::new(4.0, 0.0, 0.0),
        Vector3::new(0.0, 4.0, 0.0),
        0.02,
        &grey,
    );
    let cam = vga();
    let a = render_frame(&mesh, cam, &Pose::identity());
    let b = render_frame(&mesh, cam, &left_increment(&Vector6::new(0.01, 0.0, 0.0, 0.0, 0.0, 0.0)));
    let (model, scene) = (build_map(&a), build_map(&b));
    let mut ws = RegistrationWorkspace::new(MapCapacity::for_image(640 * 480).nodes);
    let r = register(&model, &scene, &Pose::identity(), &RegistrationParams::default(), &mut ws);
    println!("{r:?}");
    assert!(matches!(r, Err(RegistrationError::Degenerate { .. })), "{r:?}");
}

/// A model without contours (as fused models are) against a scene with them: the
/// scene's contour nodes cannot match (§3.4: contours match only contours), which
/// registration knows without searching; the motion is still recovered.
#[test]
fn a_model_without_contours_registers_a_scene_with_contours() {
    let camera = vga().halved();
    let motion = left_increment(&Vector6::new(0.01, -0.005, 0.008, 0.01, -0.006, 0.004));
    let mesh = room(11);
    let a = render_frame(&mesh, camera, &Pose::identity());
    let b = render_frame(&mesh, camera, &motion);
    let no_contours = mrsmap::map::MapParams { mark_foreground_borders: false, ..Default::default() };
    let model = build_map_with(&a, no_contours);
    let scene = build_map(&b);
    assert_eq!(model.contour_levels(), 0);
    assert_ne!(scene.contour_levels() & 1, 0, "the room's depth jumps give contours at the finest level");
    let mut ws = RegistrationWorkspace::new(MapCapacity::for_image((camera.width * camera.height) as usize).nodes);
    let r = register(&model, &scene, &Pose::identity(), &RegistrationParams::default(), &mut ws).expect("registers");
    let (t, deg) = pose_error(&r.model_from_scene, &motion);
    assert!(t < 0.005 && deg < 0.5, "error {t} m, {deg} deg");
}

/// The clustered covariance (cluster-robust sandwich + Eq. 6) is never below Eq. (6),
/// and it grows where neighbouring associations share a misfit, which Eq. (6) cannot
/// see: a block of the scene's depths 2 % too far (a miscalibrated region of a sensor).
#[test]
fn the_clustered_covariance_covers_eq6_and_grows_with_a_shared_misfit() {
    let mesh = room(2);
    let camera = vga();
    let motion = left_increment(&Vector6::new(0.01, -0.005, 0.01, 0.005, -0.01, 0.0));
    let model = build_map(&render_frame(&mesh, camera, &Pose::identity()));
    let scene_frame = render_frame(&mesh, camera, &motion);
    let mut ws = RegistrationWorkspace::new(MapCapacity::for_image((camera.width * camera.height) as usize).nodes);
    let mut widening = |frame: &mrsmap::synthetic::RenderTarget| {
        let r = register(&model, &build_map(frame), &Pose::identity(), &RegistrationParams::default(), &mut ws)
            .expect("registers");
        let excess = r.clustered_covariance - r.covariance;
        let smallest = excess.symmetric_eigenvalues().min();
        assert!(smallest >= -1e-9 * r.covariance.norm(), "clustered below Eq. 6: eigenvalue {smallest:e}");
        let trace = |c: &nalgebra::Matrix6<f64>| (0..3).map(|i| c[(i, i)]).sum::<f64>();
        (trace(&r.clustered_covariance) / trace(&r.covariance)).sqrt()
    };
    let exact = widening(&scene_frame);
    let mut warped = scene_frame.clone();
    let width = camera.width as usize;
    for (i, d) in warped.depth.iter_mut().enumerate() {
        let (u, v) = (i % width, i / width);
        if u < width / 3 && v < 240 && *d > 0 {
            *d = (*d as f64 * 1.02).round() as u16;
        }
    }
    let shared = widening(&warped);
    println!("clustered / Eq. 6 standard deviation (translation): exact {exact:.2}, shared misfit {shared:.2}");
    assert!(exact >= 1.0 && shared > 1.5 * exact, "exact {exact:.2}, shared misfit {shared:.2}");
}

/// A textured sphere turned about its centre: its shape is the same at every turn, so
/// Eq. (5) alone cannot see the turn (the registration finds no constraint on it); the
/// colour term (`RegistrationParams::color_term`, not in the paper) recovers it from
/// the texture.
#[test]
fn the_colour_term_sees_a_turn_that_the_shape_does_not() {
    use mrsmap::registration::ColorTerm;
    use mrsmap::synthetic::Mesh;
    use mrsmap::synthetic::scene::{ColorField, add_sphere};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    let center = Vector3::new(0.02, -0.03, 0.8);
    let mut sphere = Mesh::default();
    add_sphere(&mut sphere, center, 0.15, 0.005, &ColorField::new(&mut Pcg32::new(11), 12));
    // Turned by 3° about an axis through the centre: model_from_scene is the inverse turn.
    let about_center = |angle: f64| {
        let turn = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angle);
        Translation3::from(center) * turn * Translation3::from(-center)
    };
    let mut turned = sphere.clone();
    turned.transform(&about_center(3f64.to_radians()));
    let (model, scene) = (
        build_map(&render_frame(&sphere, vga(), &Pose::identity())),
        build_map(&render_frame(&turned, vga(), &Pose::identity())),
    );
    let expected = about_center(-3f64.to_radians());
    let mut ws = RegistrationWorkspace::new(MapCapacity::for_image(640 * 480).nodes);
    let plain = register(&model, &scene, &Pose::identity(), &RegistrationParams::default(), &mut ws);
    let with_color = RegistrationParams { color_term: Some(ColorTerm::default()), ..RegistrationParams::default() };
    let colored = register(&model, &scene, &Pose::identity(), &with_color, &mut ws).expect("registers with colour");
    // The error of the turn, and where the estimate puts the sphere's centre.
    let (_, deg) = pose_error(&colored.model_from_scene, &expected);
    let c = nalgebra::Point3::from(center);
    let t = (colored.model_from_scene * c - expected * c).norm();
    println!("with colour: centre off by {:.3} mm, turn by {:.3} deg", t * 1e3, deg);
    match plain {
        Err(RegistrationError::Degenerate { rotation_std_rad, .. }) => assert!(rotation_std_rad > 0.02),
        Ok(r) => {
            let (_, plain_deg) = pose_error(&r.model_from_scene, &expected);
            println!("without colour: {plain_deg:.3} deg off");
            assert!(plain_deg > 1.5, "without colour the turn is not seen: {plain_deg:.3} deg off");
        }
        Err(e) => panic!("without colour: {e}"),
    }
    assert!(t < 1e-3 && deg < 0.5, "with colour: centre off by {:.3} mm, turn by {:.3} deg", t * 1e3, deg);
}
