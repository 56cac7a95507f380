//! Ray–plane tests in `f32`: the hit of a camera or bounce ray, and the occlusion of a segment, which
//! reads only which side of the plane its two ends lie on (no division, no parallel threshold).

use glam::Vec3A;

use super::ShapeHit;

/// The hit with `t` in (`tmin`, `tmax`) of the ray `origin + t·dir` (unit `dir`) on the plane through
/// `point` with unit `normal`.
#[inline]
pub fn intersect(
    (point, normal): (Vec3A, Vec3A),
    (origin, dir): (Vec3A, Vec3A),
    (tmin, tmax): (f32, f32),
) -> Option<ShapeHit> {
    let denom = normal.dot(dir);
    if denom.abs() < 1e-12 {
        return None; // parallel: no hit (or the whole line, which has measure zero)
    }
    let t = normal.dot(point - origin) / denom;
    if t > tmin && t < tmax {
        Some(ShapeHit {
            t,
            position: origin + t * dir,
            normal,
        })
    } else {
        None
    }
}

/// True if the open segment `origin + t·dir`, `t` in (`tmin`, `tmax`), crosses the plane: its ends' sides
/// ([`crosses`]); an infinite `tmax` takes the side the ray heads to (none when it runs parallel).
#[inline]
pub fn hits_segment(
    (point, normal): (Vec3A, Vec3A),
    (origin, dir): (Vec3A, Vec3A),
    (tmin, tmax): (f32, f32),
) -> bool {
    let (side, along) = (normal.dot(origin - point), normal.dot(dir));
    crosses(side + tmin * along, side + tmax * along)
}

/// Whether a segment crosses a plane, from n·(x - q) at its two ends (signed distances, or any values of
/// the same signs): the ends lie strictly on opposite sides. The one plane occlusion test, of the
/// renderer's shadow rays and of the fitness kernel's lanes.
#[inline(always)]
pub fn crosses(side_from: f32, side_to: f32) -> bool {
    side_from * side_to < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The side test decides as the hit does, for segments that end short of, beyond and on either
    /// side of the plane, and for a ray that runs parallel to it.
    #[test]
    fn the_sides_decide_as_the_hit_does() {
        let plane = (Vec3A::new(0.0, 0.5, 0.0), Vec3A::Y);
        for (o, l) in [
            ([0.0, 1.0, 0.0], [0.3, -1.0, 0.2]),
            ([0.0, 1.0, 0.0], [0.3, 0.75, 0.2]),
            ([0.0, 0.2, 0.0], [1.0, 3.0, -2.0]),
            ([0.0, 0.2, 0.0], [1.0, 0.1, -2.0]),
            ([0.0, 1.0, 0.0], [4.0, 1.0, 0.0]),
        ] {
            let (o, l) = (Vec3A::from_array(o), Vec3A::from_array(l));
            let (dir, dist) = ((l - o).normalize(), (l - o).length());
            for tmax in [dist, f32::INFINITY] {
                let hit = intersect(plane, (o, dir), (0.0, tmax)).is_some();
                assert_eq!(
                    hits_segment(plane, (o, dir), (0.0, tmax)),
                    hit,
                    "{o} -> {l}"
                );
            }
            let (q, n) = plane;
            assert_eq!(
                crosses(n.dot(o - q), n.dot(l - q)),
                hits_segment(plane, (o, dir), (0.0, dist))
            );
        }
    }
}
