// Angle bracket: base plate and upright, a 45-degree gusset, bolt holes.
// Every round surface has $fn = 32 (facets turn by 11.25 degrees, below the
// 20-degree crease angle); every designed edge turns by 45 degrees or more.
$fn = 32;
difference() {
    union() {
        cube([60, 40, 6]);
        cube([6, 40, 45]);
        // gusset: a right triangle 24 x 24 in the x-z plane, 6 thick
        translate([0, 17, 0]) rotate([90, 0, 0]) translate([0, 0, -6])
            linear_extrude(height = 6) polygon([[6, 6], [30, 6], [6, 30]]);
    }
    for (y = [10, 30]) translate([42, y, -1]) cylinder(r = 4, h = 8);
    for (y = [10, 30]) translate([-1, y, 32]) rotate([0, 90, 0]) cylinder(r = 3.5, h = 8);
}
