//! The study code on the paper's oscillator (exact FMU integration), kept small.

use std::path::{Path, PathBuf};

use tether_study::{
    convergence, stability, Axis, Class, Convergence, JobResult, Kind, Overrides, Plan,
    ReferenceSpec, Scale, Stability, Study, StudyResults, Variant,
};

fn system_file(dir: &Path) -> PathBuf {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        name = "two-mass oscillator"
        [experiment]
        stop = 0.2
        step = 1e-3
        [method]
        kind = "baumgarte"
        beta = 2e-3
        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}
        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = 2.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}
        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        fmu = fmu.display()
    );
    let path = dir.join("oscillator.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn variant(dir: &Path, label: &str, set: &str) -> Variant {
    let mut spec = tether_master::SystemSpec::from_file(&system_file(dir)).unwrap();
    let o: Overrides = toml::from_str(set).unwrap();
    o.apply(&mut spec).unwrap();
    Variant {
        label: label.into(),
        spec,
    }
}

#[test]
fn index2_converges_with_order_two_against_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let v = variant(dir.path(), "index 2", "");
    let study = Convergence {
        steps: vec![2e-3, 1e-3],
        reference: ReferenceSpec::Named("two-mass-oscillator".into()),
        columns: vec!["mass1.x".into(), "mass1.v".into()],
    };
    let curves = convergence(&[v], &study, dir.path(), &|| {}).unwrap();
    let c = &curves[0];
    assert_eq!(c.points.len(), 2);
    let p = c.order.unwrap();
    eprintln!(
        "errors {:?}, order {p}",
        c.points.iter().map(|p| p.error).collect::<Vec<_>>()
    );
    assert!((1.8..2.3).contains(&p), "order {p}");
    // The global error is the larger of the column errors; v dominates.
    for pt in &c.points {
        assert_eq!(pt.error, pt.errors[0].max(pt.errors[1]));
        assert!(pt.errors[1] > pt.errors[0]);
    }
}

#[test]
fn the_finest_run_as_reference_gives_the_same_order() {
    let dir = tempfile::tempdir().unwrap();
    let v = variant(dir.path(), "index 2", "");
    let study = Convergence {
        steps: vec![4e-3, 2e-3, 2.5e-4],
        reference: ReferenceSpec::Named("finest".into()),
        columns: vec!["mass1.v".into()],
    };
    let curves = convergence(&[v], &study, dir.path(), &|| {}).unwrap();
    let steps: Vec<f64> = curves[0].points.iter().map(|p| p.step).collect();
    assert_eq!(steps, [4e-3, 2e-3], "the reference run is not a point");
    let p = curves[0].order.unwrap();
    assert!((1.7..2.3).contains(&p), "order {p}");
}

#[test]
fn a_tiny_grid_separates_stable_and_unstable_cells() {
    // Method 1 index 1 with large Baumgarte parameters, H = 5e-3: stable at the
    // paper's c = 1000, unstable at c = 1e5 (the paper's Fig. 7a: large c).
    let dir = tempfile::tempdir().unwrap();
    let v = variant(
        dir.path(),
        "index 1",
        "step = 5e-3\nstop = 1.0\nmethod = { kind = 'baumgarte', beta = 0.2, gamma = 1e-2 }",
    );
    let axis = |targets: &[&str], values: Vec<f64>| Axis {
        targets: targets.iter().map(|t| t.to_string()).collect(),
        label: None,
        values: Some(values),
        from: None,
        to: None,
        points: None,
        scale: Scale::Log,
    };
    let study = Stability {
        x: axis(&["mass1.c", "mass2.c"], vec![1e3, 1e5]),
        y: axis(&["mass1.d", "mass2.d"], vec![10.0]),
        growth: Some(1.0),
        monitor: vec!["mass1.v".into()],
    };
    let maps = stability(&[v], &study, &|| {}).unwrap();
    let classes: Vec<Class> = maps[0].cells.iter().map(|c| c.class).collect();
    assert_eq!(
        classes,
        [Class::Stable, Class::Unstable],
        "{:?}",
        maps[0].cells
    );
    assert!(
        maps[0].cells[1].reason.contains("diverged") || maps[0].cells[1].reason.contains("grew")
    );
}

#[test]
fn a_study_file_writes_csv_summary_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    system_file(dir.path());
    let path = dir.path().join("study.toml");
    std::fs::write(
        &path,
        r#"
        title = "index 3 with k = 0 and k = 1"
        system = "oscillator.toml"
        formats = ["svg", "png"]
        [set]
        method = { kind = "baumgarte" }
        stop = 0.1
        [[variant]]
        label = "k = 0"
        [[variant]]
        label = "k = 1"
        order = 1
        stop = 1.0
        [series]
        columns = ["mass1.x", "*.lambda"]
        "#,
    )
    .unwrap();
    let study = Study::from_file(&path).unwrap();
    assert!(matches!(study.kind, Kind::Series(_)));
    let out = dir.path().join("out");
    let report = study.run(&out, &|| {}).unwrap();
    for ext in ["csv", "txt", "svg", "png"] {
        let f = out.join(format!("study.{ext}"));
        assert!(
            std::fs::metadata(&f).unwrap().len() > 100,
            "{}",
            f.display()
        );
    }
    // Index 3 with k = 1 diverges (the paper's conclusion); the summary says so.
    assert!(
        report.summary.contains("k = 0: completed"),
        "{}",
        report.summary
    );
    assert!(
        report.summary.contains("k = 1: stopped: coupling diverged"),
        "{}",
        report.summary
    );
    let svg = std::fs::read_to_string(out.join("study.svg")).unwrap();
    assert!(svg.contains("link.lambda") && svg.contains("stopped at t"));
}

#[test]
fn bad_studies_name_the_culprit() {
    let dir = tempfile::tempdir().unwrap();
    system_file(dir.path());
    let write = |text: &str| {
        let p = dir.path().join("bad.toml");
        std::fs::write(&p, text).unwrap();
        p
    };
    let e = Study::from_file(&write("system = \"oscillator.toml\"\n[series]\n[convergence]\nsteps=[1e-3,2e-3]\nreference=\"finest\"\ncolumns=[\"mass1.x\"]\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("exactly one"), "{e}");
    let e = Study::from_file(&write(
        "system = \"oscillator.toml\"\nbogus = 1\n[series]\n",
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("bogus"), "{e}");
    // An unknown instance in a target and an unknown FMU parameter.
    for (target, word) in [("mass3.c", "mass3"), ("mass1.spring", "spring")] {
        let study = Study::from_file(&write(&format!(
            "system = \"oscillator.toml\"\n[stability]\nx = {{ targets = [\"{target}\"], values = [1.0, 2.0] }}\ny = {{ targets = [\"step\"], values = [1e-3] }}\n"
        )))
        .unwrap();
        let e = study.run(dir.path(), &|| {}).unwrap_err().to_string();
        assert!(e.contains(word), "{e}");
    }
    let study = Study::from_file(&write(
        "system = \"oscillator.toml\"\n[series]\ncolumns = [\"mass1.phi\"]\n",
    ))
    .unwrap();
    let e = study.run(dir.path(), &|| {}).unwrap_err().to_string();
    assert!(e.contains("mass1.phi") && e.contains("mass1.x"), "{e}");
}

#[test]
fn a_plan_after_a_toml_round_trip_gives_the_local_results_job_by_job() {
    // What a cluster does with a plan: jobs run one at a time, in any order,
    // from the plan's TOML, then put together. Same numbers as the local study.
    let dir = tempfile::tempdir().unwrap();
    system_file(dir.path());
    let path = dir.path().join("map.toml");
    std::fs::write(
        &path,
        r#"
        system = "oscillator.toml"
        [set]
        step = 5e-3
        stop = 0.5
        method = { kind = "baumgarte", beta = 0.2, gamma = 1e-2 }
        [stability]
        x = { targets = ["mass1.c", "mass2.c"], from = 1e2, to = 1e5, points = 3, scale = "log" }
        y = { targets = ["mass1.d", "mass2.d"], values = [0.1, 10.0] }
        growth = 1.0
        monitor = ["mass1.v"]
        "#,
    )
    .unwrap();
    let study = Study::from_file(&path).unwrap();
    let local = study.run(&dir.path().join("local"), &|| {}).unwrap();
    let plan = Plan::new(&study, study.variants().unwrap());
    let plan = Plan::from_toml(&plan.to_toml().unwrap()).unwrap();
    let n = plan.check().unwrap();
    assert_eq!(n, 6);
    let mut results: Vec<(usize, JobResult)> = (0..n)
        .rev()
        .map(|i| (i, plan.run_jobs(&[i]).unwrap().remove(0)))
        .collect();
    results.sort_by_key(|r| r.0);
    let results = plan
        .results(results.into_iter().map(|r| r.1).collect())
        .unwrap();
    let remote = study
        .report(&results, Some(&dir.path().join("remote")))
        .unwrap();
    assert_eq!(local.summary, remote.summary);
    let csv = |d: &str| std::fs::read(dir.path().join(d).join("map.csv")).unwrap();
    assert_eq!(csv("local"), csv("remote"));
    let StudyResults::Stability(maps) = results else {
        panic!("a stability study")
    };
    assert!(maps[0].cells.iter().any(|c| c.class == Class::Stable));
    assert!(maps[0].cells.iter().any(|c| c.class == Class::Unstable));
}
