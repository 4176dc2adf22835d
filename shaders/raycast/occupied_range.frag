// How far along this pixel's ray a face of the occupied bricks lies, as an entry (the ray
// meets its outside) or an exit; blended with MIN over all the faces into (least entry,
// -greatest exit). The distance is the ray caster's t: from the eye (perspective) or
// from the plane through it (orthographic, along the view).
#version 330 core

#ifndef ORTHO
#define ORTHO 0
#endif

uniform vec3 u_eye;          // relative to the volume box's lower corner
uniform vec3 u_forward;
in vec3 v_position;
flat in vec3 v_normal;
out vec2 f_range;

void main() {
    vec3 to_face = v_position - u_eye;
#if ORTHO
    float t = dot(to_face, u_forward);
    bool entry = dot(v_normal, u_forward) < 0.0;
#else
    float t = length(to_face);
    bool entry = dot(v_normal, to_face) < 0.0;
#endif
    f_range = entry ? vec2(t, 3e38) : vec2(3e38, -t);
}
