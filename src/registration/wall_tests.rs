//! Registration's parts on maps of synthetic walls: association's cache of search
//! results is exact (a fresh pass after earlier passes, whose results it reuses where
//! they provably still hold, pairs every scene node as a pass from scratch does), and
//! the trilinear interpolation of model surfels (§4.3) blends the same mean and
//! covariance with and without its Jacobian, which matches finite differences (as does
//! the blended colour's, for the colour term); and
//! registrations that start their searches from the last one's matches give the same
//! results as registrations without them, or, with a first pass from those matches
//! (`start_from_last_matches`), search around them and end as well.

use super::associate::{AssociationInput, DirCandidates, associate};
use super::evaluate::{Sum, SumInput, interpolate, slot_offsets};
use super::params::RegistrationParams;
use super::workspace::{Association, Partial, PassState};
use super::{RegistrationWorkspace, register};
use crate::frame::RgbdFrame;
use crate::geometry::se3::compose_left;
use crate::geometry::{CameraModel, NO_DISTORTION, PinholeIntrinsics, Pose};
use crate::map::{MAX_LEVELS, MapBuilder, MapCapacity, MapParams, NONE, SurfelMap};
use nalgebra::Vector6;

/// The test images' size.
pub(super) const W: usize = 320;
pub(super) const H: usize = 240;

/// The map of one `W × H` image (a QVGA-like pinhole camera, depth in 0.2 mm units).
pub(super) fn map_of_image(rgb: &[u8], depth: &[u16]) -> SurfelMap {
    let intrinsics = PinholeIntrinsics { fx: 268.0, fy: 270.0, cx: 160.0, cy: 124.0 };
    let camera =
        CameraModel { width: W as u32, height: H as u32, intrinsics, distortion: NO_DISTORTION, depth_scale_m: 0.0002 };
    let frame = RgbdFrame::new(0, camera, rgb, depth).expect("consistent frame");
    let capacity = MapCapacity::for_image(W * H);
    let mut map = SurfelMap::new(MapParams::default(), capacity).expect("valid parameters");
    MapBuilder::new(W, H, capacity.surfels).build(&frame, &mut map).expect("builds");
    map
}

/// A map of a slanted wall with a colour ramp. `scene`: a band painted another colour
/// (its nodes find candidates nearby that fail the colour gate), and the left half
/// 28 mm farther away (its finest nodes' candidates lie just beyond their search radius
/// of 25 mm, until the steps bring them within).
fn wall(scene: bool) -> SurfelMap {
    let far = |u: usize| if scene && u < W / 2 { 140 } else { 0 };
    let depth: Vec<u16> = (0..W * H).map(|i| 3000 + far(i % W) + (i % W) as u16 * 3 + (i / W) as u16).collect();
    let rgb: Vec<u8> = (0..W * H)
        .flat_map(|i| {
            let (u, v) = (i % W, i / W);
            if scene && (200..260).contains(&u) { [20, 200, 40] } else { [(u / 2) as u8, 90, (v / 2) as u8] }
        })
        .collect();
    map_of_image(&rgb, &depth)
}

/// The state association keeps between the passes of one registration.
struct Passes {
    assoc: Vec<Association>,
    last_cube: Vec<Association>,
    partials: Vec<Partial>,
    passes: Vec<PassState>,
}

impl Passes {
    fn new(scene: &SurfelMap, params: &RegistrationParams) -> Self {
        let n = scene.nodes().len();
        let slots = slot_offsets(scene, params.finest_level, params.coarsest_level)[MAX_LEVELS];
        Passes {
            assoc: vec![Association::NONE; n],
            last_cube: vec![Association::NONE; n],
            partials: vec![Partial::ZERO; slots],
            passes: Vec::new(),
        }
    }

    fn associate(&mut self, model: &SurfelMap, scene: &SurfelMap, pose: &Pose, fresh: bool) {
        let params = RegistrationParams::default();
        let terms = SumInput::new(model, scene, pose, &params, false);
        let dirs = DirCandidates::new(pose, params.view_dir_min_cos);
        let input = AssociationInput {
            terms: &terms,
            params: &params,
            dirs,
            model_contours: model.contour_levels(),
            seeds: &[],
        };
        let state = (&mut self.assoc[..], &mut self.last_cube[..]);
        associate(&input, state, &mut self.partials, &mut self.passes, fresh, Sum::LmCost, false);
    }
}

#[test]
fn a_fresh_pass_reusing_earlier_searches_pairs_as_a_pass_from_scratch() {
    let (model, scene) = (wall(false), wall(true));
    let params = RegistrationParams::default();
    let mut poses = vec![Pose::identity()];
    for k in 1..12 {
        // Steps of 0.1–1 mm and mrad, as late in LM, and 1.5 mm towards the camera.
        let s = 1e-4 * (1 + k % 10) as f64;
        let step = Vector6::new(s, -0.5 * s, -1e-3, 0.2 * s, s, -0.4 * s);
        poses.push(compose_left(&step, &poses[k - 1]));
    }
    let mut cached = Passes::new(&scene, &params);
    let (mut fresh_passes, mut reused_without_match) = (0, 0);
    for (k, pose) in poses.iter().enumerate() {
        let fresh = k % 3 != 1;
        cached.associate(&model, &scene, pose, fresh);
        if !fresh {
            continue;
        }
        let mut scratch = Passes::new(&scene, &params);
        scratch.associate(&model, &scene, pose, true);
        let pairs =
            |p: &Passes| p.assoc.iter().map(|a| (a.covered, a.scene_surfel, a.model_surfel)).collect::<Vec<_>>();
        assert_eq!(pairs(&cached), pairs(&scratch), "fresh pass {k}");
        let this_pass = (cached.passes.len() - 1) as u16;
        reused_without_match += cached
            .assoc
            .iter()
            .filter(|a| !a.covered && a.valid_radius >= 0.0 && !a.is_matched() && a.pass < this_pass)
            .count();
        fresh_passes += 1;
    }
    let matched = cached.assoc.iter().filter(|a| a.is_matched()).count();
    assert!(fresh_passes >= 7 && matched > 200, "{fresh_passes} fresh passes, {matched} matched");
    // The recoloured band's nodes find candidates that fail the colour gate; their
    // results without a match are reused while no candidate can come within the radius.
    assert!(reused_without_match > 100, "{reused_without_match} results without a match reused");
}

#[test]
fn the_interpolated_mean_s_jacobian_matches_finite_differences_and_a_cost_needs_none() {
    let (model, scene) = (wall(false), wall(true));
    let params = RegistrationParams::default();
    let mut passes = Passes::new(&scene, &params);
    passes.associate(&model, &scene, &Pose::identity(), true);
    let (mut checked, mut agree, mut color_agree, mut color_moves) = (0, 0, 0, 0);
    for a in passes.assoc.iter().filter(|a| a.is_matched()) {
        let s = &scene.surfels()[a.scene_surfel as usize];
        let res = model.resolution(s.level as usize);
        let at = |p: &nalgebra::Vector3<f64>| interpolate::<true, false>(&model, a.model_node, a.model_surfel, p, res);
        let colored =
            |p: &nalgebra::Vector3<f64>| interpolate::<true, true>(&model, a.model_node, a.model_surfel, p, res);
        let p = s.mean.cast::<f64>();
        let (full, cost_only) = (at(&p), interpolate::<false, false>(&model, a.model_node, a.model_surfel, &p, res));
        assert_eq!((full.mean, full.cov), (cost_only.mean, cost_only.cov));
        assert_eq!(cost_only.jacobian, nalgebra::Matrix3::zeros());
        // Without COLOR the colour is the matched surfel's; with it, the blend changes
        // nothing else, and its cost-only form has the same colour and no Jacobian.
        let matched = model.surfels()[a.model_surfel as usize].color.cast::<f64>();
        assert_eq!((full.color, full.color_jacobian), (matched, nalgebra::Matrix3::zeros()));
        let (with_color, color_cost) =
            (colored(&p), interpolate::<false, true>(&model, a.model_node, a.model_surfel, &p, res));
        assert_eq!((with_color.mean, with_color.cov, with_color.jacobian), (full.mean, full.cov, full.jacobian));
        assert_eq!((color_cost.color, color_cost.color_jacobian), (with_color.color, nalgebra::Matrix3::zeros()));
        // Central differences, a thousandth of a cell: the blend is piecewise smooth, so
        // a step that crosses a cell centre may disagree; nearly all must not.
        let h = 1e-3 * res;
        let numeric = |f: &dyn Fn(&nalgebra::Vector3<f64>) -> nalgebra::Vector3<f64>| {
            nalgebra::Matrix3::from_fn(|i, j| {
                let e = nalgebra::Vector3::ith(j, h);
                (f(&(p + e))[i] - f(&(p - e))[i]) / (2.0 * h)
            })
        };
        let close = |n: nalgebra::Matrix3<f64>, j: nalgebra::Matrix3<f64>| n - j;
        checked += 1;
        let mean_error = close(numeric(&|q| at(q).mean), full.jacobian);
        agree += usize::from(mean_error.amax() <= 1e-6 + 1e-4 * full.jacobian.amax());
        let color_error = close(numeric(&|q| colored(q).color), with_color.color_jacobian);
        color_agree += usize::from(color_error.amax() <= 1e-6 + 1e-4 * with_color.color_jacobian.amax());
        color_moves += usize::from(with_color.color_jacobian.amax() > 0.05);
    }
    assert!(checked > 500 && agree as f64 >= 0.95 * checked as f64, "{agree} of {checked} Jacobians agree");
    assert!(color_agree as f64 >= 0.95 * checked as f64, "{color_agree} of {checked} colour Jacobians agree");
    // The wall's colour ramp: the blended colour changes along it.
    assert!(color_moves as f64 >= 0.5 * checked as f64, "{color_moves} of {checked} colours change with p");
}

#[test]
fn matches_remembered_from_the_last_registration_change_nothing_but_the_order_of_visits() {
    let (model, scene) = (wall(false), wall(true));
    let params = RegistrationParams::default();
    let mut remembering = RegistrationWorkspace::new(scene.nodes().len());
    remembering.remember_matches();
    let nudged = compose_left(&Vector6::new(0.004, -0.003, 0.002, 0.01, -0.005, 0.003), &Pose::identity());
    // The first registration fills the memory; the next ones start their searches from it.
    for (k, start) in [Pose::identity(), Pose::identity(), nudged, nudged].iter().enumerate() {
        let seeded = register(&model, &scene, start, &params, &mut remembering);
        let seeds = remembering.seeds.iter().filter(|&&s| s != NONE).count();
        let plain = register(&model, &scene, start, &params, &mut RegistrationWorkspace::new(scene.nodes().len()));
        assert_eq!(format!("{seeded:?}"), format!("{plain:?}"), "registration {k}");
        assert!(seeded.is_ok(), "registration {k}: {seeded:?}");
        assert!((k == 0) == (seeds == 0) && (k == 0 || seeds > 200), "registration {k}: {seeds} seeds");
    }
    // Matches remembered against another model are indices into the wrong arena: they
    // must neither fail nor change the result.
    let other = wall(true);
    let seeded = register(&other, &scene, &nudged, &params, &mut remembering);
    let plain = register(&other, &scene, &nudged, &params, &mut RegistrationWorkspace::new(scene.nodes().len()));
    assert_eq!(format!("{seeded:?}"), format!("{plain:?}"), "another model");
}

#[test]
fn a_first_pass_from_the_last_matches_searches_around_them_and_lm_ends_where_it_does_from_scratch() {
    let (model, scene) = (wall(false), wall(true));
    let params = RegistrationParams { start_from_last_matches: true, ..RegistrationParams::default() };
    let fresh_ws = || RegistrationWorkspace::new(scene.nodes().len());
    let mut remembering = fresh_ws();
    remembering.remember_matches();
    let nudged = compose_left(&Vector6::new(0.004, -0.003, 0.002, 0.01, -0.005, 0.003), &Pose::identity());
    // Without a memory the first pass searches from scratch: the paper's registration.
    let first = register(&model, &scene, &nudged, &params, &mut remembering);
    let plain = register(&model, &scene, &nudged, &params, &mut fresh_ws());
    assert_eq!(format!("{first:?}"), format!("{plain:?}"));
    // The next registration starts near where that one ended, as a tracker's next frame.
    let last = first.expect("registers").model_from_scene;
    let start = compose_left(&Vector6::new(0.003, 0.002, -0.002, -0.004, 0.003, 0.002), &last);
    // One pass alone (no LM step, no Newton): the remembered matches' neighbourhoods were
    // searched (a cube only where a node has none), and matched about as many nodes as
    // cubes do from scratch.
    let one_pass = RegistrationParams { lm_max_iterations: 0, newton_iterations: 0, ..params };
    let matched_by =
        |ws: &RegistrationWorkspace, cube: bool| ws.assoc.iter().filter(|a| a.is_matched() && a.cube == cube).count();
    let mut seeded_ws = remembering.clone();
    let _ = register(&model, &scene, &start, &one_pass, &mut seeded_ws);
    let mut plain_ws = fresh_ws();
    let _ = register(&model, &scene, &start, &one_pass, &mut plain_ws);
    let (around, in_cubes, cubes) =
        (matched_by(&seeded_ws, false), matched_by(&seeded_ws, true), matched_by(&plain_ws, true));
    assert_eq!(matched_by(&plain_ws, false), 0);
    assert!(
        around > 10 * in_cubes && around as f64 >= 0.9 * cubes as f64 && cubes > 500,
        "{around} matched around the seeds and {in_cubes} in cubes, {cubes} in cubes from scratch"
    );
    // The whole registration still ends after a pass from scratch, at the same optimum.
    let seeded = register(&model, &scene, &start, &params, &mut remembering).expect("registers");
    let plain = register(&model, &scene, &start, &params, &mut fresh_ws()).expect("registers");
    let d = seeded.model_from_scene * plain.model_from_scene.inverse();
    // (The wall holds the pose loosely, its halves disagree by 28 mm: the two paths of LM
    // end about a millimetre apart, equally good.)
    assert!(seeded.converged && plain.converged);
    assert!(seeded.mean_mahalanobis2 <= 1.01 * plain.mean_mahalanobis2, "{seeded:?} {plain:?}");
    assert!(seeded.associations as f64 >= 0.98 * plain.associations as f64, "{seeded:?} {plain:?}");
    assert!(d.translation.vector.norm() < 2e-3 && d.rotation.angle() < 5e-3, "{d:?}");
    // A failed registration leaves no memory: the next starts from scratch.
    let unrelated = map_of_image(&vec![128; W * H * 3], &vec![0; W * H]);
    assert!(register(&model, &unrelated, &start, &params, &mut remembering).is_err());
    let after = register(&model, &scene, &start, &params, &mut remembering);
    assert_eq!(format!("{after:?}"), format!("{:?}", register(&model, &scene, &start, &params, &mut fresh_ws())));
    assert!(remembering.seeds.iter().all(|&s| s == NONE));
}
