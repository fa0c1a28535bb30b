//! The 14 measurement geometries (SCIENCE.md §2) and the directions derived from them.
//!
//! Right-handed frame, surface normal +z, light always at azimuth φ = 0. Angles come from the
//! table below, never from the digits of a geometry's name: X-Rite's `<detector>as<aspecular>`
//! names do not say on which side of the normal the light is.

use std::fmt;

/// Which instrument measures a geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Device {
    /// X-Rite MA-T12 multi-angle spectrophotometer: 31-band reflectance factor.
    MaT12,
    /// Canon RA-532H surface reflectance analyser: one achromatic 1D-BRDF intensity.
    Sra,
}

impl Device {
    /// The key used for this device in the scan file and the store.
    pub const fn key(self) -> &'static str {
        match self {
            Device::MaT12 => "ma_t12",
            Device::Sra => "sra",
        }
    }
}

impl From<drivers::Instrument> for Device {
    /// The instrument a driver speaks to is the device its readings belong to.
    fn from(instrument: drivers::Instrument) -> Device {
        match instrument {
            drivers::Instrument::MaT12 => Device::MaT12,
            drivers::Instrument::Sra => Device::Sra,
        }
    }
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Device::MaT12 => "X-Rite MA-T12",
            Device::Sra => "Canon RA-532H",
        })
    }
}

/// One measurement geometry: in-plane light and view directions, in degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Position in [`GEOMETRIES`] (0-based; the table's "#" minus one).
    pub index: usize,
    pub device: Device,
    /// The device's own name for the geometry, stored with every reading.
    pub name: &'static str,
    /// Light zenith angle θi, degrees.
    pub theta_i_deg: f64,
    /// View zenith angle θr, degrees.
    pub theta_r_deg: f64,
    /// View azimuth φr, degrees: 180 = far side of the normal (toward the mirror direction),
    /// 0 = same side as the light (toward back-scatter).
    pub phi_r_deg: f64,
    /// Aspecular angle, degrees, as in the device's name.
    pub aspecular_deg: f64,
}

const fn g(
    index: usize,
    device: Device,
    name: &'static str,
    theta_i_deg: f64,
    theta_r_deg: f64,
    phi_r_deg: f64,
    aspecular_deg: f64,
) -> Geometry {
    Geometry {
        index,
        device,
        name,
        theta_i_deg,
        theta_r_deg,
        phi_r_deg,
        aspecular_deg,
    }
}

/// Number of geometries in a full scan.
pub const GEOMETRY_COUNT: usize = 14;
/// Number of MA-T12 geometries (the first 12 of [`GEOMETRIES`]).
pub const MA_T12_COUNT: usize = 12;
/// Number of SRA geometries (the last 2 of [`GEOMETRIES`]).
pub const SRA_COUNT: usize = 2;

/// SCIENCE.md §2, in table order: 12 MA-T12 geometries, then the 2 SRA ones.
pub const GEOMETRIES: [Geometry; GEOMETRY_COUNT] = {
    use Device::{MaT12 as M, Sra as S};
    [
        g(0, M, "15as-45", 60.0, 15.0, 180.0, -45.0),
        g(1, M, "15as-30", 45.0, 15.0, 180.0, -30.0),
        g(2, M, "15as-15", 30.0, 15.0, 180.0, -15.0),
        g(3, M, "15as15", 0.0, 15.0, 180.0, 15.0),
        g(4, M, "15as45", 30.0, 15.0, 0.0, 45.0),
        g(5, M, "15as80", 65.0, 15.0, 0.0, 80.0),
        g(6, M, "45as-15", 60.0, 45.0, 180.0, -15.0),
        g(7, M, "45as15", 30.0, 45.0, 180.0, 15.0),
        g(8, M, "45as25", 20.0, 45.0, 180.0, 25.0),
        g(9, M, "45as45", 0.0, 45.0, 180.0, 45.0),
        g(10, M, "45as75", 30.0, 45.0, 0.0, 75.0),
        g(11, M, "45as110", 65.0, 45.0, 0.0, 110.0),
        g(12, S, "sra-20", 20.0, 20.0, 180.0, 0.0),
        g(13, S, "sra-60", 60.0, 60.0, 180.0, 0.0),
    ]
};

/// The MA-T12's 12 geometries, in table order.
pub fn ma_t12() -> &'static [Geometry] {
    &GEOMETRIES[..MA_T12_COUNT]
}

/// The SRA's 2 geometries, in table order.
pub fn sra() -> &'static [Geometry] {
    &GEOMETRIES[MA_T12_COUNT..]
}

/// Geometries of one device, in table order.
pub fn of_device(device: Device) -> &'static [Geometry] {
    match device {
        Device::MaT12 => ma_t12(),
        Device::Sra => sra(),
    }
}

/// Looks a geometry up by its device name (exact match).
pub fn by_name(name: &str) -> Option<&'static Geometry> {
    GEOMETRIES.iter().find(|g| g.name == name)
}

/// A set of the 14 geometries: which ones a scan measured and a fit takes part in. A full scan
/// has all 14; a scan from an MA-T12 alone ([`GeometrySet::MA_T12`]) has the first 12. Cost
/// functions, evaluations and reports take their means over the geometries of the set only.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct GeometrySet(u16);

impl GeometrySet {
    /// All 14 geometries (both instruments).
    pub const ALL: GeometrySet = GeometrySet((1 << GEOMETRY_COUNT) - 1);
    /// The 12 MA-T12 geometries: a scan without SRA readings.
    pub const MA_T12: GeometrySet = GeometrySet((1 << MA_T12_COUNT) - 1);

    /// The set without geometry `index` (leave-one-out prediction).
    pub const fn without(self, index: usize) -> GeometrySet {
        GeometrySet(self.0 & !(1 << index))
    }

    /// Whether the geometry at `index` (table order) is in the set.
    pub const fn contains(self, index: usize) -> bool {
        index < GEOMETRY_COUNT && self.0 & (1 << index) != 0
    }

    /// How many geometries the set holds.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether the set is empty (no fit can be made over it).
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Whether every SRA geometry is in the set.
    pub const fn has_sra(self) -> bool {
        self.0 & !Self::MA_T12.0 == !Self::MA_T12.0 & Self::ALL.0
    }

    /// The geometries of the set, in table order.
    pub fn iter(self) -> impl Iterator<Item = &'static Geometry> {
        GEOMETRIES.iter().filter(move |g| self.contains(g.index))
    }
}

impl Default for GeometrySet {
    fn default() -> Self {
        GeometrySet::ALL
    }
}

impl fmt::Debug for GeometrySet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter().map(|g| g.name)).finish()
    }
}

/// A unit vector in the surface frame (normal = +z).
pub type Vec3 = [f64; 3];

fn direction(theta_deg: f64, phi_deg: f64) -> Vec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
}

impl Geometry {
    /// Direction toward the light, l (φ = 0).
    pub fn light(&self) -> Vec3 {
        direction(self.theta_i_deg, 0.0)
    }

    /// Direction toward the viewer (detector), v.
    pub fn view(&self) -> Vec3 {
        direction(self.theta_r_deg, self.phi_r_deg)
    }

    /// cos θi, the cosine weight w_g of the cost functions (SCIENCE.md §5).
    pub fn cos_theta_i(&self) -> f64 {
        self.theta_i_deg.to_radians().cos()
    }

    /// cos θr.
    pub fn cos_theta_r(&self) -> f64 {
        self.theta_r_deg.to_radians().cos()
    }

    /// Half vector h = normalize(l + v).
    pub fn half(&self) -> Vec3 {
        let (l, v) = (self.light(), self.view());
        let s = [l[0] + v[0], l[1] + v[1], l[2] + v[2]];
        let n = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        [s[0] / n, s[1] / n, s[2] / n]
    }
}

impl fmt::Display for Geometry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_indexed_in_order() {
        for (i, geo) in GEOMETRIES.iter().enumerate() {
            assert_eq!(geo.index, i);
            assert_eq!(by_name(geo.name).unwrap().index, i);
        }
        assert!(by_name("15as 45").is_none());
    }

    /// The drivers' tables are the wire truth: this table must name the same geometries, in the
    /// same order, per instrument.
    #[test]
    fn names_match_the_drivers_tables() {
        for (device, instrument) in [
            (Device::MaT12, drivers::Instrument::MaT12),
            (Device::Sra, drivers::Instrument::Sra),
        ] {
            let ours: Vec<&str> = of_device(device).iter().map(|g| g.name).collect();
            assert_eq!(ours, instrument.geometries(), "{device}");
            assert_eq!(device.key(), instrument.key());
        }
    }

    #[test]
    fn aspecular_matches_the_angles() {
        // Far side: θr − θi; same side: θr + θi (SCIENCE.md §2).
        for geo in &GEOMETRIES {
            let expected = if geo.phi_r_deg == 180.0 {
                geo.theta_r_deg - geo.theta_i_deg
            } else {
                geo.theta_r_deg + geo.theta_i_deg
            };
            assert_eq!(geo.aspecular_deg, expected, "{}", geo.name);
        }
    }

    #[test]
    fn geometry_sets() {
        assert_eq!(GeometrySet::ALL.len(), GEOMETRY_COUNT);
        assert_eq!(GeometrySet::MA_T12.len(), MA_T12_COUNT);
        assert!(GeometrySet::ALL.has_sra());
        assert!(!GeometrySet::MA_T12.has_sra());
        assert!(!GeometrySet::ALL.without(13).has_sra());
        assert!(
            GeometrySet::MA_T12
                .iter()
                .all(|g| g.device == Device::MaT12)
        );
        let loo = GeometrySet::MA_T12.without(3);
        assert_eq!(loo.len(), 11);
        assert!(!loo.contains(3) && loo.contains(2) && !loo.contains(14));
        assert_eq!(
            format!(
                "{:?}",
                GeometrySet::ALL
                    .without(0)
                    .without(1)
                    .without(2)
                    .without(3)
                    .without(4)
                    .without(5)
                    .without(6)
                    .without(7)
                    .without(8)
                    .without(9)
                    .without(10)
                    .without(11)
            ),
            "[\"sra-20\", \"sra-60\"]"
        );
    }

    #[test]
    fn sra_geometries_look_at_the_mirror_direction() {
        for geo in sra() {
            let h = geo.half();
            assert!((h[2] - 1.0).abs() < 1e-12, "{}: h = {h:?}", geo.name);
        }
    }
}
