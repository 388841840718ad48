//! Cross-validation on real data (three views, two folds, one epoch): every view is held out
//! exactly once, the pooled table counts the right images, and a second call on the same folder
//! resumes the finished folds instead of optimizing again.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::progress::{Progress, Silent};
use pav::studies::crossval::crossval;
use pav::studies::curve::{pool, CurveOptions};
use pav::studies::per_view::{conditional_asr, paired};
use pav::table::unique;
use std::cell::RefCell;

/// Records what crossval reports, in order.
#[derive(Default)]
struct Stages {
    seen: RefCell<Vec<String>>,
}

impl Progress for Stages {
    fn begin(&self, label: &str, total: u64) {
        self.seen.borrow_mut().push(format!("{label}/{total}"));
    }
    fn advance(&self, n: u64) {
        self.seen.borrow_mut().push(format!("+{n}"));
    }
    fn status(&self, msg: &str) {
        self.seen.borrow_mut().push(msg.to_string());
    }
    fn end(&self, _kept: Option<&str>) {
        self.seen.borrow_mut().push("end".into());
    }
}
use pav::attack::setup::Setup;
use pav::attack::whitebox::Ensemble;
use std::sync::atomic::AtomicBool;

#[test]
fn every_view_is_held_out_once_and_finished_folds_resume() {
    common::real_data();
    let path = common::repo().join("configs/studies/half.toml");
    let mut cfg = OptimizeConfig::load(&path).unwrap();
    cfg.views.train = cfg.views.train[1..3].to_vec();
    cfg.views.test = cfg.views.test[..1].to_vec();
    cfg.optimizer.epochs = 1;
    let setup = Setup::load(&cfg, None).unwrap();
    let wb = Ensemble::load(&cfg, cfg.views.size).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // A peer's texture at its own size (2048²), resampled to the atlas; rendered views over
    // plates are tested in tests/it/blender_views.rs (they need Blender).
    let rauca = setup.load_texture(&common::shared_data().join("rauca-e2e/RAUCA_E2E.png")).unwrap();
    let (mut opts, mut dets) = common::two_folds(dir.path(), 2, vec![("RAUCA_E2E".into(), rauca)], Vec::new());
    // A snapshot every step: the start and each step, scored on the fold's photos; and the mean
    // of the snapshots from step 1 on.
    opts.curve = CurveOptions { every: 1, mean_from: Some(1) };
    let never = AtomicBool::new(false);
    let stages = Stages::default();
    let cv = crossval(&path, &cfg, &setup, &wb, &mut dets, &opts, &stages, &never).unwrap();
    let (rows, recs) = (&cv.rows, &cv.records);
    assert_eq!(
        *stages.seen.borrow(),
        ["folds/4", "fold 1/2: optimizing", "fold 1/2: scoring the snapshots", "fold 1/2: scoring", "+1"]
            .into_iter()
            .chain(["fold 1/2: done", "+1", "fold 2/2: optimizing", "fold 2/2: scoring the snapshots"])
            .chain(["fold 2/2: scoring", "+1", "fold 2/2: done", "+1", "end"])
            .collect::<Vec<_>>()
    );
    let mut held: Vec<String> =
        recs.iter().filter(|r| r.role == "held-out" && r.texture == "original").map(|r| r.view.clone()).collect();
    held.sort();
    assert_eq!(held, ["data12501", "data12502", "data12503"]);
    let cell = |t: &str, split: &str| rows.iter().find(|r| r.texture == t && r.split == split).unwrap().images;
    assert_eq!((cell("original", "held-out"), cell("optimized", "held-out"), cell("random", "held-out")), (3, 3, 6));
    assert_eq!((cell("RAUCA_E2E", "held-out"), cell("random32", "held-out")), (3, 6));
    // Optimized against each other texture, paired by view: three held-out views each.
    let pairs = paired(recs, &opts.white_box, "optimized");
    let against: Vec<(&str, usize)> = pairs.iter().map(|p| (p.against.as_str(), p.views)).collect();
    let expected = [("original", 3), ("snapshot-mean-from-1", 3), ("random", 3), ("random32", 3), ("RAUCA_E2E", 3)];
    assert_eq!(against, expected, "{pairs:?}");
    assert!(pairs.iter().all(|p| p.lo <= p.mean && p.mean <= p.hi && p.white_box));
    // ASR over the held-out views the original paint is detected on: those views only.
    let cond = conditional_asr(recs, 0.5);
    let detected = recs.iter().filter(|r| r.role == "held-out" && r.texture == "original" && r.score >= 0.5).count();
    assert_eq!(cond.len(), 5);
    assert!(cond.iter().all(|c| c.views == detected && (0.0..=1.0).contains(&c.asr)), "{cond:?}");
    assert_eq!(cell("optimized", "train"), 3, "each view trains in the one fold that does not hold it out");
    assert!(recs.iter().all(|r| r.score.is_finite() && (0.0..=1.0).contains(&r.score)));
    // The curve: fold 1 trains on one view (steps 0 and 1), fold 2 on two (0, 1, 2); each
    // snapshot scored on the fold's three photos. A fold's last snapshot is its texture saved in
    // 8 bits, so it scores as the optimized texture did, to within that rounding.
    let steps = |f: usize| unique(cv.curve.iter().filter(|c| c.fold == f).map(|c| c.step));
    assert_eq!((steps(0), steps(1)), (vec![0, 1], vec![0, 1, 2]));
    assert_eq!(cv.curve.len(), 5 * 3);
    for c in cv.curve.iter().filter(|c| c.last && c.role == "held-out") {
        let r = recs.iter().find(|r| r.fold == c.fold && r.view == c.view && r.texture == "optimized").unwrap();
        assert!((c.score - r.score).abs() < 0.02, "{c:?} vs {r:?}");
    }
    // The mean of the snapshots from step 1, scored as a texture of its own on every photo: in
    // fold 1 that is its last snapshot alone, the optimized texture in 8 bits; in fold 2 the mean
    // of steps 1 and 2. The optimized texture is paired against it like any other.
    let means: Vec<_> = recs.iter().filter(|r| r.texture == "snapshot-mean-from-1").collect();
    assert_eq!(means.len(), 2 * 3);
    for m in means.iter().filter(|m| m.fold == 0) {
        let r = recs.iter().find(|r| r.fold == 0 && r.view == m.view && r.texture == "optimized").unwrap();
        assert!((m.score - r.score).abs() < 0.02, "{m:?} vs {r:?}");
    }
    assert!(rows.iter().any(|r| r.texture == "snapshot-mean-from-1" && r.split == "held-out"));
    assert!(dir.path().join("fold1of2/snapshot-mean-from-1.png").is_file());
    assert!(cv.anatomies.iter().any(|a| a.texture == "snapshot-mean-from-1"));
    let pooled = pool(&cv.curve);
    let held: Vec<(f64, bool, usize)> =
        pooled.iter().filter(|p| p.role == "held-out").map(|p| (p.step, p.last, p.n)).collect();
    assert_eq!(held, [(0.0, false, 3), (1.5, true, 3)], "step 1 is not a step both folds reached before their end");
    // Both folds wrote their texture; a second call finds them finished and scores the same.
    for f in 0..2 {
        assert!(dir.path().join(format!("fold{f}of2/texture.png")).is_file());
    }
    let t = std::time::Instant::now();
    let cv2 = crossval(&path, &cfg, &setup, &wb, &mut dets, &opts, &Silent, &never).unwrap();
    let (rows2, recs2) = (&cv2.rows, &cv2.records);
    eprintln!("resumed in {:.1} s", t.elapsed().as_secs_f64());
    assert_eq!(recs.iter().map(|r| r.score).collect::<Vec<_>>(), recs2.iter().map(|r| r.score).collect::<Vec<_>>());
    assert_eq!(rows.len(), rows2.len());
    assert!(cv.rendered.is_none(), "no rendered views given, none scored");

    // The held-out boxes: each view's best box is its recorded best score, every IoU is in
    // [0, 1] against the view's ground truth, and the anatomy counts each image once.
    assert!(!cv.boxes.is_empty());
    for r in recs.iter().filter(|r| r.role == "held-out") {
        let best = cv
            .boxes
            .iter()
            .filter(|b| {
                b.fold == r.fold
                    && b.view == r.view
                    && b.texture == r.texture
                    && b.seed == r.seed
                    && b.detector == r.detector
            })
            .map(|b| b.score)
            .fold(0.0, f32::max);
        assert_eq!(best, r.score, "{r:?}");
    }
    assert!(cv.boxes.iter().all(|b| (0.0..=1.0).contains(&b.iou) && b.x0 < b.x1 && b.y0 < b.y1));
    let an = |t: &str| cv.anatomies.iter().find(|a| a.texture == t).unwrap();
    assert_eq!((an("original").images, an("random").images, an("RAUCA_E2E").images), (3, 6, 3));
    for a in &cv.anatomies {
        assert!((0.0..=1.0).contains(&a.on_car) && a.on_score <= a.on_car && a.off_boxes >= 0.0, "{a:?}");
    }
    // The original paint leaves a box on the car in every held-out view (it is detected in all three).
    assert_eq!(an("original").on_car, 1.0, "{:?}", an("original"));

    // The transfer table reads the run back from its CSVs: the optimized row carries the run's
    // held-out cells, the baselines come once, and the differences are the run's own pairs.
    pav::table::write_csv(&dir.path().join("crossval.csv"), rows).unwrap();
    pav::table::write_csv(&dir.path().join("crossval_views.csv"), recs).unwrap();
    pav::table::write_csv(&dir.path().join("crossval_anatomy.csv"), &cv.anatomies).unwrap();
    pav::table::write_csv(&dir.path().join("crossval_boxes.csv"), &cv.boxes).unwrap();
    let runs = [("tiny".to_string(), dir.path().to_path_buf()), ("again".to_string(), dir.path().to_path_buf())];
    let t = pav::studies::table1::table1(&runs, &[]).unwrap();
    let held = |t: &str| rows.iter().find(|r| r.texture == t && r.split == "held-out").unwrap();
    let cell = |row: &str| t.cells.iter().find(|c| c.row == row).unwrap();
    assert_eq!(
        t.cells.iter().map(|c| c.row.as_str()).collect::<Vec<_>>(),
        ["original", "random", "random32", "RAUCA_E2E", "tiny", "again"]
    );
    assert_eq!((cell("tiny").mean_score, cell("tiny").p50), (held("optimized").mean_score, held("optimized").p50));
    assert_eq!(cell("RAUCA_E2E").mean_score, held("RAUCA_E2E").mean_score);
    assert!(cell("tiny").white_box && !cell("random").white_box);
    assert_eq!(t.baseline_spread, 0.0);
    // The snapshot mean is the run's own texture, not a baseline: table1 leaves it out.
    let mine: Vec<(&str, f64)> = t.differences[..3].iter().map(|d| (d.against.as_str(), d.mean)).collect();
    let want: Vec<(&str, f64)> = pairs[2..].iter().map(|p| (p.against.as_str(), p.mean)).collect();
    assert_eq!(mine, want, "the run against random, random32 and RAUCA_E2E, as crossval paired them");
    let md = t.markdown();
    assert!(md.contains(&format!("**{:.3} / ", held("optimized").mean_score)), "{md}");
    // Per held-out view: the label's scores are the run's own, the random rows their seeds' mean.
    let view_of = |tex: &str, r: &pav::studies::per_view::ScoredView| {
        t.views
            .iter()
            .find(|v| v.texture == tex && (v.fold, &v.view, &v.detector) == (r.fold, &r.view, &r.detector))
            .unwrap()
            .score
    };
    let held_recs: Vec<_> = recs.iter().filter(|r| r.role == "held-out").collect();
    for r in held_recs.iter().filter(|r| r.texture == "optimized") {
        assert_eq!(view_of("tiny", r), r.score);
        assert_eq!(view_of("again", r), r.score);
    }
    for r in held_recs.iter().filter(|r| r.texture == "random") {
        let seeds: Vec<f32> = held_recs
            .iter()
            .filter(|x| x.texture == "random" && (x.fold, &x.view, &x.detector) == (r.fold, &r.view, &r.detector))
            .map(|x| x.score)
            .collect();
        assert!(
            seeds.len() > 1 && (view_of("random", r) - seeds.iter().sum::<f32>() / seeds.len() as f32).abs() < 1e-6
        );
    }
    assert!(t.views.iter().all(|v| v.texture != "optimized" && v.seed == 0));
    // On the photos it trained on: per photo the mean of its train-role scores over the folds
    // that trained on it, against the same photo held out and against RAUCA-E2E's score there.
    let trained_of = |view: &str, det: &str| {
        let s: Vec<f64> = recs
            .iter()
            .filter(|r| r.role == "train" && r.texture == "optimized" && r.view == view && r.detector == det)
            .map(|r| r.score as f64)
            .collect();
        assert!(!s.is_empty(), "{view} trains in some fold");
        s.iter().sum::<f64>() / s.len() as f64
    };
    let dets = unique(recs.iter().map(|r| r.detector.clone()));
    assert_eq!(t.trained_cells.iter().filter(|c| c.row == "tiny").count(), dets.len());
    for c in t.trained_cells.iter().filter(|c| c.row == "tiny") {
        let of: Vec<_> = held_recs.iter().filter(|r| r.texture == "optimized" && r.detector == c.detector).collect();
        let n = of.len() as f64;
        let want_t = of.iter().map(|r| trained_of(&r.view, &c.detector)).sum::<f64>() / n;
        let want_h = of.iter().map(|r| r.score as f64).sum::<f64>() / n;
        assert!((c.trained_on - want_t).abs() < 1e-6 && (c.held_out - want_h).abs() < 1e-6 && c.views == 3, "{c:?}");
        let g = t.generalization.iter().find(|d| d.row == "tiny" && d.detector == c.detector).unwrap();
        assert!(g.against == "trained-on" && (g.mean - (want_h - want_t)).abs() < 1e-6, "{g:?}");
        let rauca = |v: &str| {
            held_recs
                .iter()
                .find(|r| r.texture == "RAUCA_E2E" && r.view == v && r.detector == c.detector)
                .unwrap()
                .score as f64
        };
        let want = of.iter().map(|r| trained_of(&r.view, &c.detector) - rauca(&r.view)).sum::<f64>() / n;
        let d = t.trained_on.iter().find(|d| d.row == "tiny" && d.detector == c.detector && d.against == "RAUCA_E2E");
        assert!((d.unwrap().mean - want).abs() < 1e-6, "{d:?} vs {want}");
    }
    assert!(!t.trained_on.iter().any(|d| d.against == "original" || d.against == "optimized"));
    // The snapshot mean as the run's row: its own held-out cells, paired against the same
    // baselines as crossval paired it, with the final texture out of the table.
    let as_mean = [("mean".to_string(), dir.path().to_path_buf(), "snapshot-mean-from-1".to_string())];
    let m = pav::studies::table1::table1_of(&as_mean, &[]).unwrap();
    let rows_of = |t: &pav::studies::table1::Table1| unique(t.cells.iter().map(|c| c.row.clone()));
    assert_eq!(rows_of(&m), ["original", "random", "random32", "RAUCA_E2E", "mean"]);
    let mine = m.cells.iter().find(|c| c.row == "mean").unwrap();
    assert_eq!(mine.mean_score, held("snapshot-mean-from-1").mean_score);
    let from_mean = paired(recs, &opts.white_box, "snapshot-mean-from-1");
    let rauca = |ds: &[pav::studies::table1::Difference]| ds.iter().find(|d| d.against == "RAUCA_E2E").unwrap().mean;
    let want = from_mean.iter().find(|p| p.against == "RAUCA_E2E").unwrap().mean;
    assert!((rauca(&m.differences) - want).abs() < 1e-9, "{} vs {want}", rauca(&m.differences));
    let e =
        pav::studies::table1::table1_of(&[("x".into(), dir.path().to_path_buf(), "snapshot-mean-from-7".into())], &[])
            .unwrap_err();
    assert!(e.to_string().contains("snapshot-mean-from-7"), "{e}");
    let e = pav::studies::table1::table1(&[("x".into(), dir.path().join("fold0of2"))], &[]).unwrap_err();
    assert!(e.to_string().contains("pav crossval"), "{e}");

    // Two runs under one label make one row, averaged per view; paired with another label's
    // row, the same run differs from itself by exactly zero.
    let d = dir.path().to_path_buf();
    let runs = [("seeds".to_string(), d.clone()), ("seeds".to_string(), d.clone()), ("one".to_string(), d.clone())];
    let g = pav::studies::table1::table1(&runs, &["one".to_string()]).unwrap();
    let seeds = g.cells.iter().find(|c| c.row == "seeds").unwrap();
    assert_eq!(
        (seeds.runs, seeds.mean_score, seeds.p50_min, seeds.p50_max),
        (2, held("optimized").mean_score, held("optimized").p50, held("optimized").p50)
    );
    let vs_one = g.differences.iter().find(|x| x.row == "seeds" && x.against == "one").unwrap();
    assert_eq!((vs_one.mean, vs_one.lo, vs_one.hi, vs_one.views), (0.0, 0.0, 0.0, 3), "{vs_one:?}");
    let vs_rauca = |row: &str| g.differences.iter().find(|x| x.row == row && x.against == "RAUCA_E2E").unwrap().mean;
    assert_eq!(vs_rauca("seeds"), vs_rauca("one"));
    assert!(g.markdown().contains("| seeds |") && !g.differences.iter().any(|x| x.row == "one" && x.against == "one"));
    // The box anatomy reads back: baselines as crossval wrote them, a label's runs averaged.
    let a = |t: &str| g.anatomy.iter().find(|a| a.texture == t).unwrap();
    assert_eq!(a("RAUCA_E2E"), an("RAUCA_E2E"));
    let opt = an("optimized");
    assert_eq!((a("seeds").images, a("seeds").on_car, a("seeds").best_off), (2 * opt.images, opt.on_car, opt.best_off));
    // The car's own box: per view the best box at IoU ≥ 0.5 (0 without one), paired as the scores are.
    let own = |t: &str, view: &str| {
        cv.boxes
            .iter()
            .filter(|b| b.texture == t && b.view == view && b.iou >= 0.5)
            .map(|b| b.score)
            .fold(0.0, f32::max) as f64
    };
    let views: Vec<&str> =
        recs.iter().filter(|r| r.role == "held-out" && r.texture == "original").map(|r| r.view.as_str()).collect();
    let want = views.iter().map(|v| own("optimized", v) - own("RAUCA_E2E", v)).sum::<f64>() / views.len() as f64;
    let got = g.own_box.iter().find(|x| x.row == "seeds" && x.against == "RAUCA_E2E").unwrap();
    assert!((got.mean - want).abs() < 1e-6 && got.views == 3, "{got:?} vs {want}");
    let self_own = g.own_box.iter().find(|x| x.row == "seeds" && x.against == "one").unwrap();
    assert_eq!((self_own.mean, self_own.lo, self_own.hi), (0.0, 0.0, 0.0));
    let e = pav::studies::table1::table1(&runs, &["none".to_string()]).unwrap_err();
    assert!(e.to_string().contains("no run has that label"), "{e}");
}
