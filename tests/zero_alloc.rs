//! No heap allocation in map building and registration after the first frame, counted
//! on every thread (rayon workers included) by a global allocator.

mod common;

use common::*;
use mrsmap::frame::RgbdFrame;
use mrsmap::geometry::Pose;
use mrsmap::io::camera_file::read_camera;
use mrsmap::io::frames::FrameLoader;
use mrsmap::io::tum::TumDataset;
use mrsmap::odometry::{Odometry, OdometryParams};

#[global_allocator]
static GLOBAL: Counting = Counting;

use common::counting_alloc::{Counting, first_allocation, start_counting, stop_counting};

fn allocations_per_frame(half: bool) -> (usize, usize) {
    let camera = read_camera(&fr3_camera_file()).expect("camera");
    let dataset = TumDataset::open(&teddy_clip()).expect("clip");
    let mut loader = FrameLoader::new(camera, half);
    let cam = loader.camera();
    let frames: Vec<(Vec<u8>, Vec<u16>)> = dataset
        .frames
        .iter()
        .map(|f| {
            let fr = loader.load(f).expect("frame loads");
            (fr.rgb.to_vec(), fr.depth.to_vec())
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
    let mut odometry =
        Odometry::new(OdometryParams::default(), cam.width as usize, cam.height as usize, Pose::identity())
            .expect("params");
    let mut step = |i: usize| {
        let (rgb, depth) = &frames[i % frames.len()];
        let frame = RgbdFrame::new(i as u64, cam, rgb, depth).expect("frame");
        pool.install(|| {
            odometry.build(&frame).expect("builds");
            odometry.track()
        })
    };
    // Warm-up: the first frame sizes the ray table; a few more settle the pool.
    for i in 0..3 {
        step(i);
    }
    start_counting();
    let n = 3 * frames.len();
    for i in 3..3 + n {
        step(i);
    }
    (stop_counting(), n)
}

#[test]
fn building_and_registering_allocate_nothing_after_warm_up() {
    // One test drives everything in turn: the counter is process-wide.
    // Control: allocations on rayon worker threads are seen.
    {
        use rayon::prelude::*;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
        start_counting();
        let total: usize = pool.install(|| (0..64).into_par_iter().map(|i| vec![i; 100].len()).sum());
        let allocations = stop_counting();
        assert_eq!(total, 6400);
        assert!(allocations >= 64, "the counter must see worker allocations");
    }
    for half in [false, true] {
        let (allocations, frames) = allocations_per_frame(half);
        println!("{}: {allocations} allocations in {frames} frames", if half { "QVGA" } else { "VGA" });
        assert_eq!(allocations, 0, "{allocations} allocations in {frames} frames; the first on {}", first_allocation());
    }
}
