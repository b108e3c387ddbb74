//! The plans built into the binary: every plan the manifest lists loads, says what it is, and
//! finds the PTX of each of its modules; step and kinematics plans of one world count bind
//! their shared buffers with equal sizes (so one simulation can load both).

use std::collections::BTreeMap;

use instantmimic::plan::{DeviceType, OpKind, PlanStore, ptx_file_name, walk_ops};

#[test]
fn every_committed_plan_loads_and_finds_its_modules() {
    check_plans(&PlanStore::new(None));
}

/// The deterministic physics variant (configs/physics/deterministic.toml), shipped as a
/// directory that `--assets` names.
#[test]
fn every_deterministic_plan_loads_and_finds_its_modules() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("ptx/deterministic");
    let store = PlanStore::new(Some(&dir));
    let manifest = store
        .manifest()
        .expect("ptx/deterministic/plans/manifest.json");
    assert_eq!(
        manifest.physics["config"]["deterministic"],
        serde_json::json!(true)
    );
    check_plans(&store);
}

fn check_plans(store: &PlanStore) {
    let manifest = store.manifest().expect("the plan manifest");
    assert!(!manifest.plans.is_empty());
    let mut sizes: BTreeMap<u32, BTreeMap<String, u64>> = BTreeMap::new();
    for entry in &manifest.plans {
        let plan = store
            .plan(&entry.name, entry.nworld)
            .unwrap_or_else(|e| panic!("{} {}: {e}", entry.name, entry.nworld));
        assert_eq!(plan.header.device, DeviceType::Cuda);
        let info = plan.info().expect("packed plans carry PlanInfo");
        assert_eq!(
            (info.name.as_str(), info.nworld),
            (entry.name.as_str(), entry.nworld)
        );
        for module in &plan.modules {
            let file = ptx_file_name(&module.binary_filename).unwrap();
            let ptx = store
                .module_ptx(&module.binary_filename)
                .unwrap_or_else(|e| panic!("{file}: {e}"));
            let text = String::from_utf8_lossy(&ptx);
            for kernel in plan.kernels.iter().filter(|k| k.module_hash == module.hash) {
                assert!(
                    text.contains(&format!(".entry {}(", kernel.forward_name)),
                    "{file} lacks the entry {}",
                    kernel.forward_name
                );
            }
        }
        let mut launches = 0;
        walk_ops(&plan.ops, &mut |op, _| {
            if op.kind() == OpKind::KernelLaunch {
                launches += 1;
            }
        });
        assert!(
            launches > 0,
            "{} {} launches nothing",
            entry.name,
            entry.nworld
        );
        let shared = sizes.entry(entry.nworld).or_default();
        for binding in &plan.bindings {
            let size = plan.region(binding.region).unwrap().size;
            if let Some(&other) = shared.get(&binding.name) {
                assert_eq!(
                    other, size,
                    "{} binds {} with another size",
                    entry.name, binding.name
                );
            }
            shared.insert(binding.name.clone(), size);
        }
        for name in [
            "d.qpos",
            "d.qvel",
            "d.ctrl",
            "d.xpos",
            "d.xquat",
            "m.body_mass",
        ] {
            assert!(
                plan.binding(name).is_some(),
                "{} {} does not bind {name}",
                entry.name,
                entry.nworld
            );
        }
        println!(
            "{} {} worlds: {} modules, {} kernels, {launches} launches, {} bindings",
            entry.name,
            entry.nworld,
            plan.modules.len(),
            plan.kernels.len(),
            plan.bindings.len()
        );
    }
}

/// A store that keeps decoded plans decodes each plan once: after the first request the plan
/// comes from memory (here its file is gone), and a clone of the store shares what was
/// decoded. A plain store reads the file every time.
#[test]
fn a_keeping_store_decodes_each_plan_once_and_clones_share_it() {
    let entry = PlanStore::new(None).manifest().unwrap().plans[0].clone();
    let dir = tempfile::tempdir().unwrap();
    let plans = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("ptx/plans");
    std::fs::create_dir(dir.path().join("plans")).unwrap();
    for file in ["manifest.json", entry.file.as_str()] {
        std::fs::copy(plans.join(file), dir.path().join("plans").join(file)).unwrap();
    }
    let plain = PlanStore::new(Some(dir.path()));
    let store = PlanStore::new(Some(dir.path())).keeping_decoded();
    let first = store.plan(&entry.name, entry.nworld).unwrap();
    assert_eq!(plain.plan(&entry.name, entry.nworld).unwrap(), first);
    std::fs::remove_file(dir.path().join("plans").join(&entry.file)).unwrap();
    let again = store.clone().plan(&entry.name, entry.nworld).unwrap();
    assert_eq!(first, again);
    // A plain store reads the directory again, and says the file is missing.
    let err = plain
        .plan(&entry.name, entry.nworld)
        .unwrap_err()
        .to_string();
    assert!(err.contains(&entry.file), "{err}");
}
