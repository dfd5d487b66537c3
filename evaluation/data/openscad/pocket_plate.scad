// Plate with a rectangular pocket, a 45-degree chamfer round its top edges and
// four counterbored holes. $fn = 32: facets turn by 11.25 degrees.
$fn = 32;
c = 3;  // chamfer width
difference() {
    cube([80, 60, 12]);
    translate([20, 15, 7]) cube([40, 30, 6]);
    // chamfers: a square bar turned 45 degrees, centred on each top edge
    for (y = [0, 60]) translate([40, y, 12]) rotate([45, 0, 0])
        cube([82, c * sqrt(2), c * sqrt(2)], center = true);
    for (x = [0, 80]) translate([x, 30, 12]) rotate([0, 45, 0])
        cube([c * sqrt(2), 62, c * sqrt(2)], center = true);
    for (x = [8, 72], y = [8, 52]) {
        translate([x, y, -1]) cylinder(r = 2.5, h = 14);
        translate([x, y, 8]) cylinder(r = 4.5, h = 5);
    }
}
