#version 330 core
// Every pattern kind of capture-format.md, and the projector-only alignment grid;
// processing/projection/patterns.py is the definition this follows.
// Image row 0 is the top of the screen: v = height - gl_FragCoord.y. Pixel centres are at k + 0.5.

const int KIND_SINUSOID = 0;
const int KIND_SPECKLE_SINUSOID = 1;
const int KIND_GRAY = 2;
const int KIND_FLAT = 3;
const int KIND_GRID = 4;
const float TWO_PI = 6.283185307179586;

uniform ivec2 size;          // projector (width, height) in pixels
uniform int kind;
uniform int axis;            // 0: x (u across width), 1: y (v across height)
uniform float frequency;     // fringes across the axis
uniform float offset;
uniform float amplitude;
uniform float phase;         // phase_rad + this frame's shift, reduced to [0, 2 pi)
uniform float speckle_gain;
uniform sampler2D speckle;   // R32F (width x height) field Z of 0 / 1, row 0 = image row 0
uniform int bits;
uniform int bit;             // 0 = most significant
uniform bool inverted;
uniform bool binary;          // plain binary code (cell s carries s) instead of Gray
uniform float period_px;      // code cell width in pixels; 0: extent / 2^bits
uniform float level;
uniform int pitch_px;        // grid: line spacing, line and crosshair widths in pixels
uniform int line_px;
uniform int crosshair_px;
uniform float background;
uniform bool use_lut;
uniform sampler2D lut;       // R32F (N x 1) drive level for intensity i / (N - 1)
uniform int lut_size;

out vec4 colour;

float sinusoid(float coord, float extent) {
    // 2 pi f u / W reduced before the cosine keeps float32 accurate for high frequencies
    return offset + amplitude * cos(TWO_PI * fract(frequency * coord / extent) + phase);
}

float gray(int index, int extent) {
    // stripe = floor((k + 0.5) * 2^bits / W), in integers so that stripe borders are exact;
    // with a cell width, floor((k + 0.5) / period_px)
    uint stripes = 1u << uint(bits);
    uint stripe = period_px > 0.0
        ? uint(min(floor((float(index) + 0.5) / period_px), float(stripes - 1u)))
        : min((uint(2 * index + 1) * stripes) / uint(2 * extent), stripes - 1u);
    uint code = binary ? stripe : stripe ^ (stripe >> 1u);
    float value = float((code >> uint(bits - 1 - bit)) & 1u);
    return inverted ? 1.0 - value : value;
}

bool on_line(int offset, int width, int pitch) {
    // (offset + width / 2) mod pitch < width, for offset >= -size / 2 (no negative % in GLSL)
    int shifted = offset + width / 2 + pitch * (size.x / pitch + size.y / pitch + 2);
    return shifted % pitch < width;
}

bool on_band(int offset, int width) {
    int shifted = offset + width / 2;
    return shifted >= 0 && shifted < width;
}

float grid(ivec2 pixel) {
    ivec2 offset = pixel - size / 2;
    bool lit = on_line(offset.x, line_px, pitch_px) || on_line(offset.y, line_px, pitch_px)
        || on_band(offset.x, crosshair_px) || on_band(offset.y, crosshair_px);
    return lit ? level : background;
}

float apply_lut(float x) {
    float position = clamp(x, 0.0, 1.0) * float(lut_size - 1);
    int below = min(int(floor(position)), lut_size - 2);
    float a = texelFetch(lut, ivec2(below, 0), 0).r;
    float b = texelFetch(lut, ivec2(below + 1, 0), 0).r;
    return mix(a, b, position - float(below));
}

void main() {
    ivec2 pixel = ivec2(int(gl_FragCoord.x), size.y - 1 - int(gl_FragCoord.y));
    vec2 centre = vec2(pixel) + 0.5;
    float coord = axis == 0 ? centre.x : centre.y;
    float extent = float(axis == 0 ? size.x : size.y);
    float intensity;
    if (kind == KIND_SINUSOID) {
        intensity = sinusoid(coord, extent);
    } else if (kind == KIND_SPECKLE_SINUSOID) {
        float z = texelFetch(speckle, pixel, 0).r;
        intensity = (1.0 - speckle_gain) * sinusoid(coord, extent) + speckle_gain * z;
    } else if (kind == KIND_GRAY) {
        intensity = gray(axis == 0 ? pixel.x : pixel.y, axis == 0 ? size.x : size.y);
    } else if (kind == KIND_GRID) {
        intensity = grid(pixel);
    } else {
        intensity = level;
    }
    intensity = clamp(intensity, 0.0, 1.0);
    float drive = use_lut ? apply_lut(intensity) : intensity;
    colour = vec4(drive, drive, drive, 1.0);
}
