//! Reading numbers a model file may hold as `null`. serde_json writes NaN
//! and ±∞ as `null` and refuses `null` for an `f64`, so a descriptive number
//! that is undefined on some data (the correlation of the slopes of fewer
//! than two reliable tracks, the t-value of an exact fit) made a model file
//! `fit` wrote that nothing could read. These read `null` as NaN; the fields
//! a prediction reads are checked finite on reading instead
//! (`SavedModel::check_shapes`).

use serde::{Deserialize, Deserializer};

/// An `f64`, `null` as NaN.
pub(crate) fn f64_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// A list of `f64`, each `null` as NaN.
pub(crate) fn f64s_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    Ok(Vec::<Option<f64>>::deserialize(d)?
        .into_iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect())
}

/// A list of `f64` pairs, each `null` as NaN.
pub(crate) fn f64_pairs_or_nan<'de, D: Deserializer<'de>>(
    d: D,
) -> Result<Vec<(f64, f64)>, D::Error> {
    Ok(Vec::<(Option<f64>, Option<f64>)>::deserialize(d)?
        .into_iter()
        .map(|(a, b)| (a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN)))
        .collect())
}

#[cfg(test)]
mod tests {
    #[derive(Debug, serde::Serialize, serde::Deserialize)]
    struct Doc {
        #[serde(deserialize_with = "super::f64_or_nan")]
        x: f64,
        #[serde(deserialize_with = "super::f64s_or_nan")]
        v: Vec<f64>,
        #[serde(deserialize_with = "super::f64_pairs_or_nan")]
        p: Vec<(f64, f64)>,
    }

    #[test]
    fn what_serde_json_writes_for_nan_and_infinity_reads_back_as_nan() {
        let doc = Doc {
            x: f64::NAN,
            v: vec![1.5, f64::INFINITY],
            p: vec![(f64::NEG_INFINITY, 2.0)],
        };
        let text = serde_json::to_string(&doc).unwrap();
        assert_eq!(text, r#"{"x":null,"v":[1.5,null],"p":[[null,2.0]]}"#);
        let back: Doc = serde_json::from_str(&text).unwrap();
        assert!(back.x.is_nan() && back.v[1].is_nan() && back.p[0].0.is_nan());
        assert_eq!((back.v[0], back.p[0].1), (1.5, 2.0));
        // Numbers read as numbers; a string is still refused.
        let back: Doc = serde_json::from_str(r#"{"x":3,"v":[],"p":[]}"#).unwrap();
        assert_eq!(back.x, 3.0);
        assert!(serde_json::from_str::<Doc>(r#"{"x":"3","v":[],"p":[]}"#).is_err());
    }
}
