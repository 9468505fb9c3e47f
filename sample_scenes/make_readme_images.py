"""Render the README's sample-scene pictures into docs/images/<scene>.png (Cycles, CPU).

    ./dev python sample_scenes/make_readme_images.py [SCENE ...]

Each scene is rendered by render.py in its own process (default frames, resolution and samples of
sample_scenes.scenes.DEFAULTS unless listed below); scenes with several frames are put side by side
(the triangle: p1 = frame 150 on the left, p2 = frame 1 on the right, like the paper's figure 8),
except the scenes in SEPARATE, whose frames become one picture each, docs/images/<scene>_NNNN.png
(the fly-in: far, middle, close; the plunge: hovering at 6 r_s, at 1.28 r_s, at 1.05 r_s), and the star field's three views go to docs/images/starfield_normal.png,
starfield_dome.png and starfield_panorama.png. Prints render.py's per-frame summary for each scene.
"""
import os
import subprocess
import sys
import tempfile

from PIL import Image

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
RENDER = os.path.join(ROOT, "sample_scenes", "render.py")
OUT = os.path.join(ROOT, "docs", "images")

PICTURES = {  # scene: extra render.py arguments
    "triangle_flat": ["--frames", "150,1"],
    "triangle_tess1": ["--frames", "150,1"],
    "triangle_tess4": ["--frames", "150,1"],
    "triangle_tess64": ["--frames", "150,1"],
    "disc_90": [], "disc_30": [], "disc_10": [],
    "disc_90_external": [], "disc_30_external": [], "disc_10_external": [],
    "shell": [],
    "room": [],
    "luminet": [], "luminet_blackbody": [],
    "flyin": ["--frames", "1,120,240"],
    "plunge": ["--frames", "1,160,240"],
    "starfield": [], "starfield_dome": [], "starfield_panorama": [],
    "orbit": [], "orbit_panorama": [], "orbit_still": [], "orbit_panorama_still": [],
}
SEPARATE = {"flyin", "plunge"}  # one picture per frame: <scene>_NNNN.png
TARGETS = {"starfield": "starfield_normal"}  # picture name when it is not the scene's


def side_by_side(paths, gap=4):
    ims = [Image.open(p).convert("RGB") for p in paths]
    out = Image.new("RGB", (sum(i.width for i in ims) + gap * (len(ims) - 1), max(i.height for i in ims)))
    x = 0
    for im in ims:
        out.paste(im, (x, 0))
        x += im.width + gap
    return out


def main(names):
    os.makedirs(OUT, exist_ok=True)
    for name in names or list(PICTURES):
        with tempfile.TemporaryDirectory() as tmp:
            args = [sys.executable, RENDER, "--scene", name, "--output", tmp, *PICTURES.get(name, [])]
            p = subprocess.run(args, capture_output=True, text=True)
            if p.returncode:
                sys.exit(p.stdout[-3000:] + p.stderr[-3000:])
            for line in p.stdout.splitlines():
                if line.startswith("frame ") or "s per frame" in line:
                    print(line.replace(tmp, "<tmp>"), flush=True)
            pngs = [os.path.join(tmp, f) for f in sorted(os.listdir(tmp)) if f.endswith(".png")]
            frames = PICTURES.get(name, [])
            if "--frames" in frames:  # keep the order given
                order = [int(f) for f in frames[frames.index("--frames") + 1].split(",")]
                pngs = [os.path.join(tmp, f"{name}_{f:04d}.png") for f in order]
            if name in SEPARATE:
                outputs = [(os.path.join(OUT, os.path.basename(p)), [p]) for p in pngs]
            else:
                outputs = [(os.path.join(OUT, f"{TARGETS.get(name, name)}.png"), pngs)]
            for target, parts in outputs:
                side_by_side(parts).save(target, optimize=True)
                print(f"-> {os.path.relpath(target, ROOT)} ({os.path.getsize(target) // 1024} KB)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
