//! Presets: the science choices of a fit under one name — the model's form, the lobe's Fresnel
//! factor, how an SRA reading enters the cost and how much it weighs there (SCIENCE.md §4.1,
//! §5.1, §5.2).
//!
//! [`Preset::Measured`] is what a measured or imported scan is fitted with unless told
//! otherwise: the choices that predict best off the measured angles (held-out geometries of
//! the 47 real exports, measured goniometric BRDFs; SCIENCE.md §4.1). [`Preset::Paper`] is the
//! paper's configuration, which `brdfd demo` and the study report reproduce. A preset gives
//! defaults only: `--model`, `--fresnel`, `--sra` (or the `[fit]` keys) given beside it win.

use serde::{Deserialize, Serialize};

use crate::cost::CostFunction;
use crate::model::{FresnelCosine, ModelKind};
use crate::sra_reading::{SraModel, SraWeight};

/// A named set of defaults for the model form, Fresnel factor, SRA reading model and weight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The paper's model form with the exact dielectric Fresnel, SRA readings compared as
    /// luminance and weighed at the MA-T12 readings' level under cf1 and m2: what predicts
    /// measured materials best (the default).
    #[default]
    Measured,
    /// The paper's configuration: Schlick on cos θi, the flat grey SRA reading (paper Eq. 1–9).
    Paper,
}

impl Preset {
    /// Every preset, the default first.
    pub const ALL: [Preset; 2] = [Preset::Measured, Preset::Paper];

    /// The name on the command line and in `[fit] preset`.
    pub const fn name(self) -> &'static str {
        match self {
            Preset::Measured => "measured",
            Preset::Paper => "paper",
        }
    }

    /// The model's form: the paper's in both (Oren–Nayar and the second lobe did not predict
    /// held-out real geometries better; SCIENCE.md §4.1).
    pub const fn model(self) -> ModelKind {
        ModelKind::Paper
    }

    /// The lobe's Fresnel factor.
    pub const fn fresnel(self) -> FresnelCosine {
        match self {
            Preset::Measured => FresnelCosine::MEASURED_DEFAULT,
            Preset::Paper => FresnelCosine::Incidence,
        }
    }

    /// How an SRA reading enters the cost.
    pub const fn sra(self) -> SraModel {
        match self {
            Preset::Measured => SraModel::MEASURED_DEFAULT,
            Preset::Paper => SraModel::Flat,
        }
    }

    /// The SRA readings' weight in cost function `cost` (SCIENCE.md §5.2): balanced for cf1 and
    /// m2 under `measured` (their squared and logarithmic residuals let bright specular
    /// readings pull the diffuse colour away; balancing them predicted the measured
    /// goniometric materials better), the paper's for cf2 (its cube root keeps a bright reading
    /// from dominating; balancing predicted no better) and under `paper`.
    pub const fn sra_weight(self, cost: CostFunction) -> SraWeight {
        match (self, cost) {
            (Preset::Measured, CostFunction::Cf1 | CostFunction::M2) => SraWeight::Balanced,
            _ => SraWeight::Paper,
        }
    }
}

crate::names::choice_by_name!(
    Preset,
    "preset",
    "measured (exact Fresnel, luminance SRA: what predicts measured materials best) or paper \
     (the paper's configuration)"
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_the_paper_preset_is_the_types_defaults() {
        for p in Preset::ALL {
            assert_eq!(p.name().parse::<Preset>().unwrap(), p);
            assert_eq!(p.to_string(), p.name());
        }
        assert!("gloss".parse::<Preset>().unwrap_err().contains("measured"));
        // The paper's preset is what settings stored without these choices were fitted with.
        assert_eq!(Preset::Paper.fresnel(), FresnelCosine::default());
        assert_eq!(Preset::Paper.sra(), SraModel::default());
        assert_eq!(Preset::Paper.model(), ModelKind::default());
        assert_eq!(Preset::Measured.fresnel(), FresnelCosine::Exact);
        assert_eq!(Preset::Measured.sra(), SraModel::Luminance);
        for cost in CostFunction::ALL {
            assert_eq!(Preset::Paper.sra_weight(cost), SraWeight::default());
        }
        assert_eq!(
            Preset::Measured.sra_weight(CostFunction::Cf1),
            SraWeight::Balanced
        );
        assert_eq!(
            Preset::Measured.sra_weight(CostFunction::M2),
            SraWeight::Balanced
        );
        assert_eq!(
            Preset::Measured.sra_weight(CostFunction::Cf2),
            SraWeight::Paper
        );
    }
}
