//! The hierarchy's progress and cancelling: a cancel stops the build, the merging, the walk
//! tables and the linking; progress runs from 0 to 1 and changes nothing.

use super::*;
use crate::mesh::test_meshes::{sphere, sphere_parts};
use std::sync::Mutex;
use std::time::Duration;

fn sunlit(n: usize) -> Scene {
    let mut scene = Scene::new(sphere(n, 10.0));
    let sun = Light::sun(Vec3::new(0.2, 0.1, -1.0), [1.0; 3]).unwrap();
    scene.lights.push(sun);
    scene
}

fn render() -> HierarchySettings {
    HierarchySettings {
        profile: ProfileKind::Dipole,
        mode: Mode::Render,
        estimate_receivers: 4,
        ..Default::default()
    }
}

#[test]
fn a_false_after_the_first_call_cancels_the_build() {
    let calls = Mutex::new(Vec::<f32>::new());
    let once = |f: f32| {
        let mut c = calls.lock().unwrap();
        c.push(f);
        c.len() == 1
    };
    let got = Hierarchy::new_with_progress(sunlit(12), render(), Some(&once));
    assert!(matches!(got, Err(Error::Cancelled)));
    assert_eq!(
        calls.lock().unwrap().len(),
        2,
        "asked again after the refusal"
    );
}

#[test]
fn the_merging_itself_stops_at_a_cancel_and_counts_every_merge() {
    // A callback slower than the ticker's spacing: every step of a round asks it.
    let slow = || std::thread::sleep(crate::progress::INTERVAL + Duration::from_millis(1));
    let (p, t) = sphere_parts(8, 1.0);
    let seen = Mutex::new(Vec::<f32>::new());
    let once = |f: f32| {
        slow();
        let mut s = seen.lock().unwrap();
        s.push(f);
        s.len() == 1
    };
    let got = ClusterTree::build(&p, &t, Some(&once));
    assert!(matches!(got, Err(Error::Cancelled)));
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.len(), 2, "{seen:?}");
    assert!(seen[1] < 1.0, "cancelled only at the end: {seen:?}");
    // Not cancelled: the share of the n - 1 merges reaches 1 exactly, rising.
    let all = Mutex::new(Vec::<f32>::new());
    let record = |f: f32| {
        slow();
        all.lock().unwrap().push(f);
        true
    };
    let tree = ClusterTree::build(&p, &t, Some(&record)).unwrap();
    assert_eq!(tree.len(), 2 * t.len() - 1);
    let all = all.into_inner().unwrap();
    assert_eq!(
        (all.first(), all.last()),
        (Some(&0.0), Some(&1.0)),
        "{all:?}"
    );
    assert!(all.windows(2).all(|w| w[0] <= w[1]), "{all:?}");
}

#[test]
fn progress_runs_from_zero_to_one_and_changes_nothing() {
    let m = Material::preset("marble", 1.0).unwrap();
    for mode in [Mode::OnTheFly, Mode::Render, Mode::Incremental] {
        let settings = HierarchySettings { mode, ..render() };
        let seen = Mutex::new(Vec::<f32>::new());
        let record = |f: f32| {
            seen.lock().unwrap().push(f);
            true
        };
        let mut h =
            Hierarchy::new_with_progress(sunlit(16), settings.clone(), Some(&record)).unwrap();
        let build = std::mem::take(&mut *seen.lock().unwrap());
        let got = h.radiosity_with_progress(&m, Some(&record)).unwrap().values;
        let evaluation = seen.into_inner().unwrap();
        for s in [&build, &evaluation] {
            assert_eq!(
                (s.first(), s.last()),
                (Some(&0.0), Some(&1.0)),
                "{mode:?} {s:?}"
            );
            assert!(s.windows(2).all(|w| w[0] <= w[1]), "{mode:?} {s:?}");
        }
        let mut plain = Hierarchy::new(sunlit(16), settings).unwrap();
        assert_eq!(got, plain.radiosity(&m).unwrap().values, "{mode:?}");
    }
}

#[test]
fn a_cancel_while_building_walk_tables_stops_the_evaluation() {
    // A (g, IOR) no other test asks for, so its table is not in memory yet.
    let m = Material::new([0.5; 3], [20.0; 3], 0.35, 1.7).unwrap();
    assert!(!crate::profiles::table::tables_ready(&m));
    let settings = HierarchySettings {
        profile: ProfileKind::Cycles,
        ..render()
    };
    let mut h = Hierarchy::new(sunlit(6), settings).unwrap();
    // The table's build only asks whether to go on (NaN); everything else may go on.
    let no_tables = |f: f32| !f.is_nan();
    let got = h.radiosity_with_progress(&m, Some(&no_tables));
    assert!(matches!(got, Err(Error::Cancelled)));
    assert!(!crate::profiles::table::tables_ready(&m));
}

#[test]
fn a_cancel_while_linking_drops_the_unfinished_links() {
    let m = Material::preset("marble", 1.0).unwrap();
    let mut h = Hierarchy::new(sunlit(16), render()).unwrap();
    // The stages before the links are asked at 0 and 0.3; the first receiver refined
    // reports a little more and is told to stop.
    let until_links = |f: f32| f <= 0.3;
    let got = h.radiosity_with_progress(&m, Some(&until_links));
    assert!(matches!(got, Err(Error::Cancelled)));
    assert!(h.links().is_none(), "half-refined links were kept");
    // The next evaluation refines from the root and answers as a fresh hierarchy does.
    let again = h.radiosity(&m).unwrap().values;
    assert!(h.report().relinked);
    // Every vertex a receiver (the default): one vertex's links each, and no faces' links.
    let kept = h.links().expect("render mode keeps its links");
    assert_eq!(kept.len(), h.scene().mesh.vertex_count());
    assert!(
        h.slots.is_empty(),
        "the faces' traversal ran with vertex receivers"
    );
    let mut fresh = Hierarchy::new(sunlit(16), render()).unwrap();
    assert_eq!(again, fresh.radiosity(&m).unwrap().values);
}
