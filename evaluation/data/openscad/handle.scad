// Turned handle: a flange, a fillet (r = 4) blending its top into the shaft, the
// shaft and a hemispherical end. Turned surfaces: $fn = 48 (facets turn by 7.5
// degrees); the profile's arcs turn by 6 degrees a step. The only edges are the
// flange's two rims (90 degrees); the fillet, shaft and dome are smooth.
$fn = 48;
function arc(c, r, a0, a1, n) =
    [for (i = [0 : n]) c + r * [cos(a0 + (a1 - a0) * i / n), sin(a0 + (a1 - a0) * i / n)]];
profile = concat(
    [[0, 0], [20, 0], [20, 5]],
    arc([10, 9], 4, 270, 180, 15),
    arc([0, 35], 6, 0, 90, 15)
);
rotate_extrude() polygon(profile);
