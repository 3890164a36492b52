#version 460
// Hybrid mode's raster pass: the visibility buffer keeps the nearest triangle's instance slot and
// index within its mesh; everything else comes from re-intersecting it (frame_visibility.comp).
layout(location = 0) flat in uvec2 ids;
layout(location = 0) out uvec2 visibility;

void main() { visibility = ids; }
