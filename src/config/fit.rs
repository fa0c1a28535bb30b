//! `[fit]`: which cost functions every complete scan is fitted with, and how (method, seed,
//! preset, model, Fresnel factor, SRA model, bootstrap, cross-validation).

use std::num::NonZeroUsize;

use serde::Deserialize;

use crate::cost::CostFunction;
use crate::model::FresnelCosine;
use crate::optimise::{Method, Preset};
use crate::processing::SpecularStrategy;

use super::check::{Checker, ConfigError, S};

/// `[fit]`
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// One fit per cost function, per complete scan; no duplicates.
    pub cost_functions: Vec<CostFunction>,
    pub method: Method,
    pub seed: u64,
    /// Fits running at once (each takes one core).
    pub max_concurrent_fits: NonZeroUsize,
    /// How SRA readings become spectra (SCIENCE.md §3).
    pub specular: SpecularStrategy,
    /// The science defaults (`measured` or `paper`) that `sra`, `model` and `fresnel` take
    /// when the file does not set them ([`Preset`]).
    pub preset: Preset,
    /// How an SRA reading enters the cost: the paper's flat grey spectrum or the luminance
    /// (SCIENCE.md §5.1).
    pub sra: crate::sra_reading::SraModel,
    /// How much the SRA readings weigh in every cost function (SCIENCE.md §5.2); `None`: the
    /// preset's, which depends on the cost function ([`Preset::sra_weight`]).
    pub sra_weight: Option<crate::sra_reading::SraWeight>,
    /// The model's form (SCIENCE.md §4.1): the paper's by default.
    pub model: crate::model::ModelKind,
    /// The lobe's Fresnel factor (SCIENCE.md §4): the exact dielectric Fresnel by default.
    pub fresnel: FresnelCosine,
    /// Bootstrap resamples per fit for the parameter intervals (SCIENCE.md §10); 0 turns the
    /// intervals off.
    pub bootstrap: u32,
    /// Leave-one-geometry-out cross-validation of every stored fit (SCIENCE.md §12.5).
    pub crossval: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            cost_functions: CostFunction::ALL.to_vec(),
            method: Method::default(),
            seed: defaults::SEED,
            max_concurrent_fits: NonZeroUsize::MIN,
            specular: SpecularStrategy::default(),
            preset: Preset::default(),
            sra: Preset::default().sra(),
            sra_weight: None,
            model: Preset::default().model(),
            fresnel: Preset::default().fresnel(),
            bootstrap: defaults::BOOTSTRAP,
            crossval: true,
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    pub const SEED: u64 = 1;
    pub const BOOTSTRAP: u32 = 200;
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawFit {
    cost_functions: S<Vec<String>>,
    method: S<String>,
    seed: S<u64>,
    max_concurrent_fits: S<u64>,
    specular: S<String>,
    preset: S<String>,
    sra: S<String>,
    sra_weight: S<String>,
    model: S<String>,
    fresnel: S<String>,
    bootstrap: S<u32>,
    crossval: S<bool>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[fit]`
    pub(super) fn fit(&self, raw: &RawFit) -> Result<FitConfig, ConfigError> {
        let method = self.value(
            "fit.method",
            &raw.method,
            Method::default().name().into(),
            |m| m.parse::<Method>().map_err(|e| e.to_string()),
        )?;
        let preset = self.value(
            "fit.preset",
            &raw.preset,
            Preset::default().name().into(),
            |s| s.parse::<Preset>(),
        )?;
        Ok(FitConfig {
            cost_functions: self.value(
                "fit.cost_functions",
                &raw.cost_functions,
                CostFunction::ALL
                    .iter()
                    .map(|cf| cf.name().to_string())
                    .collect(),
                |names| {
                    let mut out: Vec<CostFunction> = Vec::new();
                    for n in &names {
                        let cf: CostFunction = n.parse().map_err(|e| format!("{e}"))?;
                        if out.contains(&cf) {
                            return Err(format!("{cf} is listed twice"));
                        }
                        out.push(cf);
                    }
                    if out.is_empty() {
                        return Err("must list at least one of \"cf1\", \"cf2\", \"m2\"".into());
                    }
                    Ok(out)
                },
            )?,
            method,
            seed: self.value("fit.seed", &raw.seed, defaults::SEED, Ok)?,
            max_concurrent_fits: self.value(
                "fit.max_concurrent_fits",
                &raw.max_concurrent_fits,
                1,
                |n| match usize::try_from(n).ok().and_then(NonZeroUsize::new) {
                    Some(n) if n.get() <= 256 => Ok(n),
                    _ => Err(format!("{n} is out of range: 1 to 256 fits at once")),
                },
            )?,
            specular: self.value(
                "fit.specular",
                &raw.specular,
                SpecularStrategy::default().name().into(),
                |s| s.parse::<SpecularStrategy>().map_err(|e| e.to_string()),
            )?,
            preset,
            sra: self.value("fit.sra", &raw.sra, preset.sra().name().into(), |s| {
                s.parse::<crate::sra_reading::SraModel>()
                    .map_err(|e| e.to_string())
            })?,
            sra_weight: match &raw.sra_weight {
                None => None,
                Some(_) => Some(self.value(
                    "fit.sra_weight",
                    &raw.sra_weight,
                    String::new(),
                    |s| s.parse::<crate::sra_reading::SraWeight>(),
                )?),
            },
            fresnel: self.value(
                "fit.fresnel",
                &raw.fresnel,
                preset.fresnel().name().into(),
                |s| s.parse::<FresnelCosine>(),
            )?,
            model: self.value("fit.model", &raw.model, preset.model().name().into(), |s| {
                let m = s.parse::<crate::model::ModelKind>()?;
                if m != crate::model::ModelKind::Paper && method == Method::Paper {
                    return Err(format!(
                        "model {m} needs the separable method (fit.method = \"separable\")"
                    ));
                }
                Ok(m)
            })?,
            bootstrap: self.value("fit.bootstrap", &raw.bootstrap, defaults::BOOTSTRAP, |n| {
                if n <= 10_000 {
                    Ok(n)
                } else {
                    Err(format!(
                        "{n} is out of range: 0 (off) to 10000 resamples; 200 gives 95 % intervals"
                    ))
                }
            })?,
            crossval: self.value("fit.crossval", &raw.crossval, true, Ok)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::parse;

    #[test]
    fn fit_settings_are_checked_by_name() {
        let c = parse(
            "[fit]\ncost_functions = [\"m2\", \"cf1\"]\nmethod = \"paper\"\nseed = 42\n\
             max_concurrent_fits = 2\nspecular = \"paper-eq9\"\n",
        )
        .unwrap();
        assert_eq!(c.fit.cost_functions, [CostFunction::M2, CostFunction::Cf1]);
        assert_eq!(c.fit.method, Method::Paper);
        assert_eq!(c.fit.seed, 42);
        assert_eq!(c.fit.max_concurrent_fits.get(), 2);
        assert_eq!(c.fit.specular, SpecularStrategy::PaperEq9);
        let cases = [
            (
                "cost_functions = [\"cf3\"]",
                "fit.cost_functions",
                "unknown cost function \"cf3\"",
            ),
            (
                "cost_functions = [\"cf1\", \"cf1\"]",
                "fit.cost_functions",
                "cf1 is listed twice",
            ),
            ("cost_functions = []", "fit.cost_functions", "at least one"),
            (
                "method = \"annealing\"",
                "fit.method",
                "unknown fit method \"annealing\"",
            ),
            (
                "max_concurrent_fits = 0",
                "fit.max_concurrent_fits",
                "out of range",
            ),
            (
                "specular = \"mirror\"",
                "fit.specular",
                "unknown specular strategy \"mirror\"",
            ),
        ];
        for (line, key, says) in cases {
            let e = parse(&format!("[fit]\n{line}\n")).unwrap_err();
            let shown = e.to_string();
            assert!(
                shown.starts_with(&format!("test.toml:2: {key}: ")),
                "{shown}"
            );
            assert!(shown.contains(says), "{shown}");
        }
    }

    #[test]
    fn sra_setting() {
        use crate::sra_reading::SraModel;
        assert_eq!(parse("").unwrap().fit.sra, SraModel::Luminance);
        let c = parse("[fit]\nsra = \"flat\"\n").unwrap();
        assert_eq!(c.fit.sra, SraModel::Flat);
        let e = parse("[fit]\nsra = \"grey\"\n").unwrap_err().to_string();
        assert!(e.contains("fit.sra") && e.contains("luminance"), "{e}");
        use crate::sra_reading::SraWeight;
        assert_eq!(parse("").unwrap().fit.sra_weight, None);
        let c = parse("[fit]\nsra_weight = \"paper\"\n").unwrap();
        assert_eq!(c.fit.sra_weight, Some(SraWeight::Paper));
        let e = parse("[fit]\nsra_weight = \"even\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("fit.sra_weight") && e.contains("balanced"),
            "{e}"
        );
    }

    #[test]
    fn preset_and_fresnel_settings() {
        use crate::model::ModelKind;
        use crate::sra_reading::SraModel;
        let measured = parse("").unwrap().fit;
        assert_eq!(measured.preset, Preset::Measured);
        assert_eq!(measured.fresnel, FresnelCosine::Exact);
        assert_eq!(measured.sra, SraModel::Luminance);
        let paper = parse("[fit]\npreset = \"paper\"\n").unwrap().fit;
        assert_eq!(
            (paper.model, paper.fresnel, paper.sra),
            (ModelKind::Paper, FresnelCosine::Incidence, SraModel::Flat)
        );
        // A key beside the preset wins over it.
        let mixed = parse("[fit]\npreset = \"paper\"\nfresnel = \"exact\"\n")
            .unwrap()
            .fit;
        assert_eq!(
            (mixed.fresnel, mixed.sra),
            (FresnelCosine::Exact, SraModel::Flat)
        );
        // Every fit of the daemon is made with the configured factor.
        for (config, want) in [
            (&measured, FresnelCosine::Exact),
            (&paper, FresnelCosine::Incidence),
        ] {
            let c = crate::config::Config {
                fit: config.clone(),
                ..Default::default()
            };
            for method in [Method::Separable, Method::Paper] {
                let s = crate::service::ServiceSettings::from_config(&c).fit_settings(
                    CostFunction::Cf1,
                    method,
                    1,
                );
                assert_eq!(s.fresnel, want);
            }
        }
        for (text, key, says) in [
            ("preset = \"gloss\"", "fit.preset", "measured"),
            ("fresnel = \"schlick\"", "fit.fresnel", "exact"),
        ] {
            let e = parse(&format!("[fit]\n{text}\n")).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains(says), "{e}");
        }
    }

    #[test]
    fn model_setting() {
        use crate::model::ModelKind;
        assert_eq!(parse("").unwrap().fit.model, ModelKind::Paper);
        let c = parse("[fit]\nmodel = \"oren-nayar\"\n").unwrap();
        assert_eq!(c.fit.model, ModelKind::OrenNayar);
        assert_eq!(
            crate::service::ServiceSettings::from_config(&c)
                .fit_settings(CostFunction::Cf2, Method::Separable, 1)
                .model,
            ModelKind::OrenNayar
        );
        let e = parse("[fit]\nmodel = \"lambert\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fit.model") && e.contains("two-lobe"), "{e}");
        let e = parse("[fit]\nmethod = \"paper\"\nmodel = \"two-lobe\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fit.model") && e.contains("separable"), "{e}");
    }
}
