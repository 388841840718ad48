//! One sentence a document states from a results table of paired differences, generated like
//! the tables: between `<!-- verdict:NAME against=LABEL -->` and `<!-- /verdict:NAME -->`, the
//! rows of `results/NAME.json` whose `against` column is LABEL, each sorted by its 95 % interval
//! into ahead (the interval below zero: the trained texture hides the car better), level
//! (across zero) and behind (above zero).

use super::{cell_interval, ResultFile};
use std::path::Path;

/// The marker kind: `<!-- verdict:NAME against=LABEL -->`.
pub const KIND: &str = "verdict";

/// Rows of one table sorted by where their interval lies: (ahead, level, behind), each the
/// first column's values.
pub fn sort(file: &ResultFile, against: &str) -> Result<[Vec<String>; 3], String> {
    let col = |want: &dyn Fn(&str) -> bool, what: &str| {
        file.columns.iter().position(|c| want(c)).ok_or_else(|| format!("no {what} column in {:?}", file.columns))
    };
    let by = col(&|c| c == "against", "`against`")?;
    let interval = col(&|c| c.contains("interval"), "interval")?;
    let mut out: [Vec<String>; 3] = Default::default();
    for row in file.rows.iter().filter(|r| r.get(by).is_some_and(|v| v == against)) {
        let (lo, hi) =
            row.get(interval).and_then(|c| cell_interval(c)).ok_or_else(|| format!("row {row:?} has no interval"))?;
        let k = if hi < 0.0 {
            0
        } else if lo > 0.0 {
            2
        } else {
            1
        };
        out[k].push(row[0].clone());
    }
    if out.iter().all(Vec::is_empty) {
        return Err(format!("no row is against `{against}`"));
    }
    Ok(out)
}

/// The sentence for `results/NAME.json` against `against`.
pub fn sentence(file: &ResultFile, name: &str, against: &str) -> Result<String, String> {
    let [ahead, level, behind] = sort(file, against)?;
    let part = |word: &str, names: &[String]| match names {
        [] => None,
        [one] => Some(format!("{word} on 1 family ({one})")),
        many => Some(format!("{word} on {} families ({})", many.len(), many.join(", "))),
    };
    let parts: Vec<String> =
        [part("ahead", &ahead), part("level", &level), part("behind", &behind)].into_iter().flatten().collect();
    Ok(format!(
        "against {against}: {} (95 % intervals of the paired difference in car score, `results/{name}.json`).",
        parts.join("; ")
    ))
}

/// The body of a verdict block whose marker says `spec` (`NAME against=LABEL`): its sentence,
/// on a line of its own.
pub fn block(spec: &str, root: &Path) -> Result<String, String> {
    let (name, against) =
        spec.split_once(" against=").ok_or_else(|| format!("`<!-- {KIND}:{spec} -->` names no `against=LABEL`"))?;
    let file = ResultFile::load(root, name).map_err(|e| e.to_string())?;
    let line = sentence(&file, name, against.trim()).map_err(|e| format!("results/{name}.json: {e}"))?;
    Ok(format!("{line}\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(rows: &[(&str, &str, &str)]) -> ResultFile {
        let json = serde_json::json!({
            "title": "t", "command": "c", "commit": "0", "inputs": {},
            "columns": ["held out", "against", "difference", "95 % interval"],
            "rows": rows.iter().map(|(h, a, i)| vec![h.to_string(), a.to_string(), "0".into(), i.to_string()]).collect::<Vec<_>>(),
        });
        serde_json::from_value(json).unwrap()
    }

    #[test]
    fn each_family_goes_where_its_interval_lies() {
        let f = table(&[
            ("a", "peer", "[−0.024, −0.008]"),
            ("b", "peer", "[−0.001, +0.007]"),
            ("c", "peer", "[+0.004, +0.028]"),
            ("d", "random", "[−0.1, −0.05]"),
            ("e", "peer", "[−0.012, −0.001]"),
        ]);
        let [ahead, level, behind] = sort(&f, "peer").unwrap();
        assert_eq!((ahead, level, behind), (vec!["a".to_string(), "e".into()], vec!["b".into()], vec!["c".into()]));
        let s = sentence(&f, "x", "peer").unwrap();
        assert!(
            s.starts_with("against peer: ahead on 2 families (a, e); level on 1 family (b); behind on 1 family (c)"),
            "{s}"
        );
        assert!(sort(&f, "nobody").is_err());
    }

    #[test]
    fn a_verdict_block_is_written_back_from_its_table_and_a_bad_marker_is_named() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(tmp.path().join("results")).unwrap();
        table(&[("a", "peer", "[−0.2, −0.1]")]).save(tmp.path(), "t").unwrap();
        // A marker quoted inside a line is text; the block after it is still written.
        let doc = "Status (`<!-- verdict:t against=peer -->`):\n<!-- verdict:t against=peer -->\nstale words\n<!-- /verdict:t -->\nmore\n";
        let new = crate::generate(doc, "d.md", tmp.path()).unwrap();
        assert_eq!(
            new,
            "Status (`<!-- verdict:t against=peer -->`):\n<!-- verdict:t against=peer -->\nagainst peer: ahead on 1 family (a) (95 % intervals of the paired difference in car score, `results/t.json`).\n<!-- /verdict:t -->\nmore\n"
        );
        assert_eq!(crate::generate(&new, "d.md", tmp.path()).unwrap(), new, "regenerating changes nothing");
        let e = crate::generate("<!-- verdict:t -->\n<!-- /verdict:t -->\n", "d.md", tmp.path()).unwrap_err();
        assert!(e.to_string().contains("against=LABEL"), "{e}");
    }
}
