// Pipe with a bolted flange: tube r 12 / 9, flange r 22, four bolt holes.
// Pipe and flange $fn = 48 (7.5 degrees), bolt holes $fn = 24 (15 degrees).
difference() {
    union() {
        cylinder(r = 12, h = 50, $fn = 48);
        cylinder(r = 22, h = 5, $fn = 48);
    }
    translate([0, 0, -1]) cylinder(r = 9, h = 52, $fn = 48);
    for (a = [45, 135, 225, 315]) rotate([0, 0, a]) translate([17, 0, -1])
        cylinder(r = 2, h = 7, $fn = 24);
}
