"""Loads brdfd's Mitsuba 3 scenes in Mitsuba itself (variant scalar_spectral) and reports, as
JSON on stdout, what tests/export_mitsuba.rs compares against brdfd's own model:

- "bsdf": per scene, per (view, light) pair of the request, per wavelength, the BSDF value
  f = eval(wi = view, wo = light) / cos(theta_light) in sr^-1;
- "mean_rgb": per scene, when asked, the mean linear sRGB of the pixels covered by the sphere
  in a Mitsuba render at the requested resolution and sample count.

Request (JSON on stdin): {"scenes": [path, ...], "pairs": [[[vx,vy,vz],[lx,ly,lz]], ...],
"wavelengths": [400, ..., 700], "render": {"res": 64, "spp": 16, "only": [scene index, ...]}
or null}; "mean_rgb" holds null for a scene not rendered ("only" absent: every scene).
"""
import json
import sys

import mitsuba as mi

mi.set_variant("scalar_spectral")


def bsdf_values(scene, pairs, wavelengths):
    bsdf = scene.shapes()[0].bsdf()
    ctx = mi.BSDFContext()
    out = []
    for view, light in pairs:
        si = mi.SurfaceInteraction3f()
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        si.wi = mi.Vector3f(*view)
        wo = mi.Vector3f(*light)
        row = []
        for nm in wavelengths:
            si.wavelengths = mi.Spectrum(float(nm))
            value = bsdf.eval(ctx, si, wo)
            row.append(float(value[0]) / light[2])
        out.append(row)
    return out


def mean_rgb(path, res, spp):
    scene = mi.load_file(path, res=res, spp=spp)
    film = scene.sensors()[0].film()
    img = mi.render(scene)
    bitmap = mi.Bitmap(img)
    # The sphere's pixels: hit by every sample. An alpha channel comes with rgba films; here
    # the covered pixels are found geometrically (orthographic camera, unit sphere).
    size = film.size()
    width, height = int(size[0]), int(size[1])
    data = list(img.array)
    channels = len(data) // (width * height)
    to_world = scene.sensors()[0].world_transform()
    total = [0.0, 0.0, 0.0]
    count = 0
    for y in range(height):
        for x in range(width):
            # Pixel centre in normalised film coordinates, then on the camera's near plane.
            u = (x + 0.5) / width
            v = (y + 0.5) / height
            ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
            hit = scene.ray_intersect(ray)
            if not hit.is_valid():
                continue
            i = (y * width + x) * channels
            for c in range(3):
                total[c] += data[i + c]
            count += 1
    return [t / max(count, 1) for t in total], count


def main():
    request = json.load(sys.stdin)
    out = {"bsdf": [], "mean_rgb": []}
    render = request.get("render")
    for i, path in enumerate(request["scenes"]):
        scene = mi.load_file(path)
        out["bsdf"].append(bsdf_values(scene, request["pairs"], request["wavelengths"]))
        if render and ("only" not in render or i in render["only"]):
            rgb, n = mean_rgb(path, render["res"], render["spp"])
            out["mean_rgb"].append({"rgb": rgb, "pixels": n})
        else:
            out["mean_rgb"].append(None)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
