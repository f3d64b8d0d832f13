//! The pose blackboard at a tracker's start while its last client lets go of it.

use mrsmap::app::tracking::{StepOutput, pose_message};
use mrsmap::io::ipc;
use std::sync::mpsc::channel;
use std::time::{Duration, Instant};

#[test]
fn a_tracker_starting_while_the_last_client_lets_go_gets_the_blackboard() {
    // A client holds the blackboard of a tracker that stopped. When it lets go, iceoryx2
    // removes the blackboard: its data segments first, its name last. A tracker starting
    // in that moment finds the name taken (so it opens instead of creating) and then the
    // data gone (`ServiceInCorruptedState`); it must create the blackboard anew, not fail.
    // Each round lets go at another moment of the tracker's start.
    let name = format!("mrsmap_test_{}_bbrace/poses", std::process::id());
    let initial = [pose_message("object", &StepOutput::new(1), 0, (0, 0), 0.0)];
    let started = Instant::now();
    for round in 0..150u32 {
        let (ready, is_ready) = channel();
        let (go, let_go) = channel::<()>();
        let client_name = name.clone();
        let client = std::thread::spawn(move || {
            let node = ipc::node("test_client").expect("node");
            // What an earlier tracker left: a blackboard with entries and no writer.
            let ipc::PosePorts { entries, writer, service } = ipc::publish_poses(&node, &client_name, &initial)
                .expect("no iceoryx2 error")
                .expect("a fresh blackboard");
            drop((entries, writer));
            ready.send(()).expect("main waits");
            let_go.recv().expect("main says when");
            // Spin a little, by the round, so that the removal meets every part of the start.
            let until = Instant::now() + Duration::from_micros(u64::from(round % 50) * 20);
            while Instant::now() < until {
                std::hint::spin_loop();
            }
            drop(service);
        });
        is_ready.recv().expect("the client holds the blackboard");
        let node = ipc::node("test_tracker").expect("node");
        go.send(()).expect("the client waits");
        let ports = ipc::publish_poses(&node, &name, &initial);
        client.join().expect("the client ends");
        let ports = ports.unwrap_or_else(|e| panic!("round {round}: {e}"));
        assert!(ports.is_ok(), "round {round}: the blackboard was kept: {:?}", ports.err());
    }
    assert!(started.elapsed() < Duration::from_secs(60), "took {:?}", started.elapsed());
}
