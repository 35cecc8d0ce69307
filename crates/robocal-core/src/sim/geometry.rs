//! Capsule geometry (used by the collision model of [`super::collision`]): capsules — the set of
//! points within a radius of a segment —, exact segment–segment and point–segment distances, a
//! half-space (the table) and a solid vertical prism (the artefact's plate and stand) with the
//! signed distance of points, segments and capsules to it. Pure geometry in SI units: nothing
//! here knows about robots or cells.

use nalgebra::{Vector2, Vector3};

use crate::kinematics::Frame;

/// A segment `a`–`b` swept by a ball of `radius` (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    /// One end of the segment, m.
    pub a: Vector3<f64>,
    /// The other end of the segment (equal to `a` for a ball), m.
    pub b: Vector3<f64>,
    /// Radius, m.
    pub radius: f64,
}

impl Capsule {
    /// The capsule of segment `a`–`b` (m) and `radius` (m); nothing is checked.
    pub fn new(a: Vector3<f64>, b: Vector3<f64>, radius: f64) -> Self {
        Self { a, b, radius }
    }

    /// The capsule expressed in the parent of `frame` (its endpoints mapped by `frame`).
    pub(crate) fn transformed(&self, frame: &Frame) -> Capsule {
        Capsule { a: frame.transform_point(&self.a), b: frame.transform_point(&self.b), radius: self.radius }
    }

    /// Distance between the two surfaces; negative when they overlap (minus the penetration depth).
    pub fn distance(&self, other: &Capsule) -> f64 {
        segment_distance(&self.a, &self.b, &other.a, &other.b) - self.radius - other.radius
    }
}

/// Segments shorter than this (m²) are points: about 1e-15 m.
const DEGENERATE_LEN2: f64 = 1e-30;

/// Parameters (s, t) ∈ [0, 1]² of a closest pair of points `p1 + s·(q1 − p1)` and
/// `p2 + t·(q2 − p2)` of two segments.
///
/// Exact minimisation of the convex quadratic |p1 + s·d1 − p2 − t·d2|² over the unit square
/// (Ericson, *Real-Time Collision Detection*, §5.1.9): the unconstrained s is clamped, t is
/// solved for it and clamped, and s is re-solved for a clamped t. Points (zero-length segments)
/// reduce to point–segment distances. Parallel segments (sin² of the angle below machine ε, where
/// the solve for s is ill-conditioned and the distance is constant along the overlap anyway)
/// start from s = 0.
pub(crate) fn closest_segment_params(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (f64, f64) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.dot(&d1);
    let e = d2.dot(&d2);
    let f = d2.dot(&r);
    if a <= DEGENERATE_LEN2 && e <= DEGENERATE_LEN2 {
        return (0.0, 0.0);
    }
    if a <= DEGENERATE_LEN2 {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(&r);
    if e <= DEGENERATE_LEN2 {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(&d2);
    let denom = a * e - b * b;
    let s = if denom > f64::EPSILON * a * e { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let t = (b * s + f) / e;
    if t < 0.0 {
        ((-c / a).clamp(0.0, 1.0), 0.0)
    } else if t > 1.0 {
        (((b - c) / a).clamp(0.0, 1.0), 1.0)
    } else {
        (s, t)
    }
}

/// Exact distance between segments `p1`–`q1` and `p2`–`q2` (either may be a point).
pub fn segment_distance(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> f64 {
    let (s, t) = closest_segment_params(p1, q1, p2, q2);
    ((p1 + (q1 - p1) * s) - (p2 + (q2 - p2) * t)).norm()
}

/// Distance from point `p` to segment `a`–`b`.
#[cfg(test)]
pub(crate) fn point_segment_distance(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    let len2 = d.dot(&d);
    let t = if len2 <= DEGENERATE_LEN2 { 0.0 } else { ((p - a).dot(&d) / len2).clamp(0.0, 1.0) };
    (a + d * t - p).norm()
}

/// The free side of a plane: points `p` with `normal · (p − point) ≥ 0` (normal of unit length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfSpace {
    /// A point of the plane, m.
    pub point: Vector3<f64>,
    /// Unit normal, pointing to the free side.
    pub normal: Vector3<f64>,
}

impl HalfSpace {
    /// The plane z = 0 of `frame` (e.g. the robot's mounting plane from T_0^W), free side +z.
    pub(crate) fn xy_plane_of(frame: &Frame) -> Self {
        Self { point: frame.t, normal: frame.r.column(2).into() }
    }

    /// Signed height of `p` above the plane (m; negative on the solid side).
    pub fn height(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(&(p - self.point))
    }

    /// Height of a capsule's lowest surface point above the plane.
    pub fn clearance(&self, c: &Capsule) -> f64 {
        self.height(&c.a).min(self.height(&c.b)) - c.radius
    }
}

/// A solid vertical prism in {W}: a convex polygon in the XY plane (counter-clockwise corners),
/// from `top` (z, m) downwards without bound (the table below closes it).
#[derive(Clone, Debug, PartialEq)]
pub struct VerticalPrism {
    corners: Vec<Vector2<f64>>,
    /// Outward unit normal of edge i (corner i → corner i+1).
    normals: Vec<Vector2<f64>>,
    /// Height of the top face, z in {W}, m.
    pub top: f64,
}

/// Iterations of the golden-section search along a segment: 0.618⁶⁰ ≈ 3e-13 of its length.
const GOLDEN_ITERATIONS: usize = 60;

impl VerticalPrism {
    /// `None` unless the corners (at least three, m) form a strictly convex counter-clockwise
    /// polygon and every coordinate and `top` are finite.
    pub fn new(corners: Vec<Vector2<f64>>, top: f64) -> Option<Self> {
        let n = corners.len();
        if n < 3 || !top.is_finite() || corners.iter().any(|c| !c.x.is_finite() || !c.y.is_finite()) {
            return None;
        }
        let mut normals = Vec::with_capacity(n);
        for i in 0..n {
            let e = corners[(i + 1) % n] - corners[i];
            let next = corners[(i + 2) % n] - corners[(i + 1) % n];
            if e.perp(&next) <= 0.0 || e.norm() == 0.0 {
                return None;
            }
            normals.push(Vector2::new(e.y, -e.x) / e.norm());
        }
        Some(Self { corners, normals, top })
    }

    /// The polygon grown by `margin` (m) on every side (each edge moved out by `margin`, corners
    /// mitred, so the result is again a polygon with the same edge directions). `None` when
    /// [`Self::new`] refuses the corners or the grown polygon.
    pub fn grown(corners: &[Vector2<f64>], margin: f64, top: f64) -> Option<Self> {
        let base = Self::new(corners.to_vec(), top)?;
        let n = corners.len();
        let grown = (0..n)
            .map(|i| {
                let (np, nn) = (base.normals[(i + n - 1) % n], base.normals[i]);
                corners[i] + (np + nn) * (margin / (1.0 + np.dot(&nn)))
            })
            .collect();
        Self::new(grown, top)
    }

    /// The polygon's corners in the XY plane, counter-clockwise, m.
    pub fn corners(&self) -> &[Vector2<f64>] {
        &self.corners
    }

    /// Signed distance of a point to the prism: Euclidean distance outside, minus the depth below
    /// the nearest face inside.
    pub(crate) fn signed_distance(&self, p: &Vector3<f64>) -> f64 {
        let xy = Vector2::new(p.x, p.y);
        let n = self.corners.len();
        let mut inside_depth = f64::NEG_INFINITY;
        for i in 0..n {
            inside_depth = inside_depth.max(self.normals[i].dot(&(xy - self.corners[i])));
        }
        let dz = p.z - self.top;
        if inside_depth <= 0.0 {
            return if dz <= 0.0 { inside_depth.max(dz) } else { dz };
        }
        let mut d2 = f64::INFINITY;
        for i in 0..n {
            let (a, b) = (self.corners[i], self.corners[(i + 1) % n]);
            let e = b - a;
            let t = ((xy - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            d2 = d2.min((a + e * t - xy).norm_squared());
        }
        let d = d2.sqrt();
        if dz <= 0.0 { d } else { d.hypot(dz) }
    }

    /// Signed distance of a segment to the prism: the minimum of the point distance along it.
    /// The signed distance to a convex set is a convex function, so a golden-section search
    /// finds its minimum on the segment to ~1e-13 of the segment's length.
    pub fn segment_signed_distance(&self, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        let d = b - a;
        let f = |t: f64| self.signed_distance(&(a + d * t));
        let (fa, fb) = (f(0.0), f(1.0));
        if d.norm_squared() <= DEGENERATE_LEN2 {
            return fa;
        }
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (0.0, 1.0);
        let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        let (mut f1, mut f2) = (f(x1), f(x2));
        for _ in 0..GOLDEN_ITERATIONS {
            if f1 <= f2 {
                hi = x2;
                (x2, f2) = (x1, f1);
                x1 = hi - g * (hi - lo);
                f1 = f(x1);
            } else {
                lo = x1;
                (x1, f1) = (x2, f2);
                x2 = lo + g * (hi - lo);
                f2 = f(x2);
            }
        }
        fa.min(fb).min(f1).min(f2)
    }

    /// Distance between a capsule's surface and the prism; negative when they overlap.
    pub(crate) fn capsule_distance(&self, c: &Capsule) -> f64 {
        self.segment_signed_distance(&c.a, &c.b) - c.radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute force: the exact point–segment distance from 4001 points spread along the first
    /// segment. Never below the true distance, and above it by at most half a sample spacing
    /// times the first segment's length (the point distance is 1-Lipschitz along the segment).
    fn brute_force(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> (f64, f64) {
        let n = 4000;
        let d = (0..=n)
            .map(|i| point_segment_distance(&(p1 + (q1 - p1) * (i as f64 / n as f64)), p2, q2))
            .fold(f64::INFINITY, f64::min);
        (d, (q1 - p1).norm() / (2.0 * n as f64))
    }

    fn v3() -> impl Strategy<Value = Vector3<f64>> {
        (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| Vector3::new(x, y, z))
    }

    /// Random segment pairs, with the special cases drawn often: the second segment parallel to
    /// the first (shifted, scaled, maybe reversed, maybe collinear), either one a point, both
    /// points, or the two identical.
    fn segment_pair() -> impl Strategy<Value = [Vector3<f64>; 4]> {
        (v3(), v3(), v3(), v3(), 0..7u8, -2.0..2.0f64).prop_map(|(p1, q1, p2, q2, kind, k)| match kind {
            0 => [p1, q1, p2, p2 + (q1 - p1) * k],
            1 => [p1, q1, p1 + (q1 - p1) * k, p1 + (q1 - p1) * (k + 0.5)],
            2 => [p1, p1, p2, q2],
            3 => [p1, q1, p2, p2],
            4 => [p1, p1, p2, p2],
            5 => [p1, q1, p1, q1],
            _ => [p1, q1, p2, q2],
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn segment_distance_matches_brute_force(s in segment_pair()) {
            let [p1, q1, p2, q2] = s;
            let exact = segment_distance(&p1, &q1, &p2, &q2);
            let (bf, tol) = brute_force(&p1, &q1, &p2, &q2);
            prop_assert!(exact <= bf + 1e-12, "exact {} above brute force {}", exact, bf);
            prop_assert!(bf - exact <= tol + 1e-12, "exact {} below brute force {} by more than {}", exact, bf, tol);
            // Symmetric in the two segments and in each segment's direction.
            let swapped = segment_distance(&q2, &p2, &q1, &p1);
            prop_assert!((swapped - exact).abs() <= 1e-12);
            let (s, t) = closest_segment_params(&p1, &q1, &p2, &q2);
            prop_assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
        }

        /// Signed distance to the prism along a segment against dense sampling of the point
        /// function (exact): never above it, never below it by more than the sampling allows.
        #[test]
        fn prism_segment_distance_matches_sampling(p in v3(), q in v3()) {
            let prism = VerticalPrism::grown(
                &[Vector2::new(0.0, 0.0), Vector2::new(0.3, 0.0), Vector2::new(0.15, 0.26)], 0.06, -0.05,
            ).unwrap();
            let n = 4000;
            let bf = (0..=n)
                .map(|i| prism.signed_distance(&(p + (q - p) * (i as f64 / n as f64))))
                .fold(f64::INFINITY, f64::min);
            let d = prism.segment_signed_distance(&p, &q);
            prop_assert!(d <= bf + 1e-12, "{} vs {}", d, bf);
            prop_assert!(bf - d <= (q - p).norm() / (2.0 * n as f64) + 1e-12, "{} vs {}", d, bf);
        }
    }

    #[test]
    fn segment_distance_known_cases() {
        let v = Vector3::new;
        // Crossing at right angles, 1 apart.
        assert_eq!(segment_distance(&v(-1.0, 0.0, 0.0), &v(1.0, 0.0, 0.0), &v(0.0, -1.0, 1.0), &v(0.0, 1.0, 1.0)), 1.0);
        // Parallel, overlapping: constant distance 2.
        assert_eq!(segment_distance(&v(0.0, 0.0, 0.0), &v(2.0, 0.0, 0.0), &v(1.0, 2.0, 0.0), &v(5.0, 2.0, 0.0)), 2.0);
        // Collinear, disjoint: gap between the ends.
        assert!(
            (segment_distance(&v(0.0, 0.0, 0.0), &v(1.0, 0.0, 0.0), &v(3.0, 0.0, 0.0), &v(2.0, 0.0, 0.0)) - 1.0).abs()
                < 1e-15
        );
        // Point to point.
        assert_eq!(segment_distance(&v(1.0, 1.0, 1.0), &v(1.0, 1.0, 1.0), &v(1.0, 1.0, 4.0), &v(1.0, 1.0, 4.0)), 3.0);
    }

    #[test]
    fn grown_triangle_moves_every_edge_out() {
        let tri = [Vector2::new(0.0, 0.0), Vector2::new(0.3, 0.0), Vector2::new(0.15, 0.15 * 3f64.sqrt())];
        let prism = VerticalPrism::grown(&tri, 0.06, -0.05).unwrap();
        // Each original corner is now 60 mm inside the two adjacent faces.
        for c in tri {
            let d = prism.signed_distance(&Vector3::new(c.x, c.y, -0.5));
            assert!((d + 0.06).abs() < 1e-12, "{d}");
        }
        // Above the top, over the interior: height above the top.
        assert!((prism.signed_distance(&Vector3::new(0.15, 0.05, 0.0)) - 0.05).abs() < 1e-15);
        assert!(VerticalPrism::new(vec![tri[0], tri[2], tri[1]], 0.0).is_none(), "clockwise is refused");
    }
}
