// Drag knob: a grip disc with 12 grooves, a stem, a D-shaped shaft bore.
// Round surfaces $fn = 48 (7.5 degrees); grooves are cut by radial boxes.
difference() {
    union() {
        cylinder(r = 15, h = 12, $fn = 48);
        translate([0, 0, 12]) cylinder(r = 6, h = 8, $fn = 48);
    }
    for (i = [0 : 11]) rotate([0, 0, i * 30 + 7.5]) translate([13.5, -1, 2])
        cube([4, 2, 12]);
    difference() {
        translate([0, 0, -1]) cylinder(r = 3, h = 16, $fn = 48);
        translate([1.8, -4, -2]) cube([4, 8, 20]);
    }
}
