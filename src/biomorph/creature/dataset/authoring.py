# ruff: noqa: E501
"""How ``species.csv`` was authored: compact anatomical descriptors laid out in the seed's frame.

The seed annotated 44 side-view skeleton images in a 1000×1000 px frame (skeleton cropped,
placed at the bottom centre). We have no rights to those images, so each species is described
here by a handful of proportions taken from general anatomical knowledge (vertebral formulas,
limb-bone proportions of the respective group, typical posture), all relative to the length
``B`` of the back (shoulder–hip chord). :func:`layout` turns these descriptors into exactly the
seed's annotation (ten 2-D Bézier control points of neck/back/tail in the 1000-px frame with
y up and the head on the left, six limb lengths in px) so the rest of the pipeline sees data of
the seed's scheme. Run ``python -m biomorph.creature.dataset.authoring`` to regenerate the CSV.

The numbers are approximations: they are meant to reproduce the *shape* of the seed's data
(which animals are long-necked, long-tailed, long-legged, how heavy) and not to be a
morphometric reference.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

# --------------------------------------------------------------------------- descriptors
#: Columns of :data:`DESCRIPTORS` (lengths relative to the back chord B, angles in degrees).
DESCRIPTOR_COLUMNS = (
    "name",
    "german",
    "class",
    "weight_kg",
    "wings",
    "legs",
    "stance",
    "posture",
    "neck_len",
    "neck_ang",
    "neck_bend",
    "back_arch",
    "back_slope",
    "tail_len",
    "tail_ang",
    "tail_bend",
    "upper_arm",
    "lower_arm",
    "hand",
    "upper_leg",
    "lower_leg",
    "foot",
    "skull",
    "skull_len",
    "girth",
    "cervical",
    "trunk",
    "caudal",
)

# Weights follow the seed's appendix C.2 (mid-range where it gives a range).
# stance: plantigrade | digitigrade | unguligrade ; posture: erect | sprawling | crouched
DESCRIPTORS_TEXT = """
blue_whale,Blauwal,mammal,120000,0,0,plantigrade,erect,0,0,0,0.04,0,1.15,3,0.02,0.10,0.10,0.22,0,0,0,whale,0.55,0.45,7,30,27
horse,Pferd,mammal,600,0,4,unguligrade,erect,0.85,50,0.10,0.04,0,0.45,65,0.05,0.27,0.32,0.33,0.36,0.34,0.40,mammal_long,0.55,0.62,7,24,18
african_elephant,Afrikanischer Elefant,mammal,4000,0,4,plantigrade,erect,0.25,20,0.0,0.06,0,0.45,80,0.0,0.45,0.38,0.15,0.50,0.33,0.14,mammal_short,0.45,0.75,7,23,28
yellow_perch,Amerikanischer Flussbarsch,fish,2,0,0,plantigrade,erect,0,0,0,0.08,0,0.80,0,0.0,0.08,0.05,0.10,0.05,0.04,0.08,fish,0.45,0.45,0,20,21
archaeopteryx,Archaeopteryx,bird,1,1,2,digitigrade,erect,0.90,55,0.15,0.03,10,1.60,10,0.02,0.65,0.60,0.70,0.55,0.75,0.45,bird,0.50,0.50,10,14,22
brachiosaurus,Brachiosaurus,reptile,35000,0,4,plantigrade,erect,2.20,60,0.05,0.05,0,1.60,10,0.05,0.60,0.42,0.20,0.55,0.36,0.15,dinosaur,0.25,0.70,13,16,45
dimetrodon,Dimetrodon,reptile,250,0,4,plantigrade,sprawling,0.20,10,0.0,0.05,0,1.20,15,0.02,0.22,0.18,0.12,0.25,0.20,0.15,reptile_short,0.45,0.45,7,20,50
magpie,Elster,bird,0.2,1,2,digitigrade,erect,0.60,60,0.20,0.02,30,0.15,20,0.0,0.55,0.65,0.60,0.45,0.80,0.50,bird,0.60,0.70,13,12,6
trout,Forelle,fish,15,0,0,plantigrade,erect,0,0,0,0.04,0,0.90,0,0.0,0.10,0.06,0.10,0.07,0.05,0.08,fish,0.35,0.35,0,30,28
bowhead_whale,Grönlandwal,mammal,75000,0,0,plantigrade,erect,0,0,0,0.08,0,1.00,2,0.0,0.12,0.12,0.20,0,0,0,whale,0.90,0.60,7,27,22
ichthyornis,Ichthyornis,bird,0.3,1,2,digitigrade,erect,0.90,50,0.20,0.03,25,0.20,20,0.0,0.70,0.75,0.70,0.45,0.65,0.35,bird,0.70,0.60,12,12,6
ichthyosaurus,Ichthyosaurus,reptile,90,0,0,plantigrade,erect,0.10,0,0,0.05,0,1.80,5,-0.05,0.12,0.10,0.25,0.08,0.06,0.12,reptile_long,0.80,0.45,8,42,80
ichthyostega,Ichthyostega,amphibian,80,0,4,plantigrade,sprawling,0.10,5,0,0.03,0,1.00,10,0.0,0.25,0.15,0.15,0.28,0.15,0.22,amphibian,0.55,0.40,1,27,30
cape_buffalo,Kaffernbüffel,mammal,600,0,4,unguligrade,erect,0.55,25,0.05,0.06,0,0.55,80,0.0,0.30,0.28,0.25,0.35,0.32,0.32,mammal_long,0.50,0.75,7,19,18
rabbit,Kaninchen,mammal,1,0,4,digitigrade,crouched,0.25,40,0.05,0.15,0,0.15,20,0.0,0.30,0.30,0.20,0.45,0.50,0.45,mammal_short,0.45,0.55,7,19,16
rock_hyrax,Klippschliefer,mammal,4,0,4,plantigrade,erect,0.30,30,0.05,0.10,0,0.05,30,0.0,0.30,0.30,0.20,0.35,0.35,0.25,mammal_short,0.50,0.60,7,30,6
tarsier,Koboldmaki,mammal,0.1,0,4,plantigrade,crouched,0.25,50,0.0,0.10,0,2.30,40,0.10,0.45,0.45,0.40,0.80,0.85,0.65,primate,0.60,0.50,7,19,27
tortoise,Landschildkröte,reptile,50,0,4,plantigrade,sprawling,0.50,30,0.15,0.30,0,0.20,30,0.0,0.35,0.22,0.15,0.30,0.20,0.15,reptile_short,0.30,0.70,8,10,18
sea_lion,Ohrenrobbe,mammal,250,0,2,plantigrade,erect,0.60,35,0.10,0.03,25,0.10,20,0.0,0.25,0.25,0.45,0.20,0.30,0.45,mammal_short,0.45,0.60,7,20,10
hero_shrew,Panzerspitzmaus,mammal,0.1,0,4,plantigrade,erect,0.20,20,0.0,0.20,0,0.60,20,0.0,0.22,0.22,0.15,0.28,0.30,0.25,mammal_long,0.55,0.50,7,26,18
parasaurolophus,Parasaurolophus walkeri,reptile,4500,0,4,digitigrade,erect,0.60,25,0.15,0.05,0,1.60,5,0.0,0.30,0.28,0.18,0.50,0.45,0.30,dinosaur,0.55,0.60,15,19,60
peloneustes,Peloneustes philarchus,reptile,100,0,0,plantigrade,erect,0.80,5,0.0,0.05,0,0.60,5,0.0,0.35,0.15,0.45,0.35,0.15,0.45,reptile_long,0.70,0.40,21,24,30
sperm_whale,Pottwal,mammal,40000,0,0,plantigrade,erect,0,0,0,0.06,0,0.95,0,0.0,0.08,0.08,0.18,0,0,0,whale,0.85,0.55,7,19,24
red_deer,Rothirsch,mammal,200,0,4,unguligrade,erect,0.75,45,0.05,0.05,0,0.15,70,0.0,0.28,0.33,0.40,0.35,0.40,0.45,mammal_long,0.45,0.55,7,19,10
harbour_seal,Seehund,mammal,125,0,2,plantigrade,erect,0.35,15,0.0,0.04,10,0.12,5,0.0,0.20,0.18,0.30,0.18,0.30,0.45,mammal_short,0.40,0.60,7,20,12
sinornis,Sinornis,bird,0.02,1,2,digitigrade,erect,0.70,55,0.20,0.03,20,0.30,15,0.0,0.65,0.70,0.60,0.50,0.70,0.40,bird,0.55,0.60,10,13,8
stegosaurus,Stegosaurus,reptile,4500,0,4,plantigrade,erect,0.50,0,-0.05,0.25,0,1.30,15,0.0,0.32,0.22,0.10,0.60,0.40,0.15,dinosaur,0.28,0.80,10,17,45
pigeon,Taube,bird,1.5,1,2,digitigrade,erect,0.55,60,0.20,0.02,30,0.12,25,0.0,0.45,0.55,0.55,0.40,0.60,0.35,bird,0.45,0.80,14,12,6
thrinaxodon,Thrinaxodon,reptile,2,0,4,plantigrade,sprawling,0.25,15,0.0,0.05,0,0.60,15,0.0,0.25,0.20,0.15,0.28,0.22,0.18,reptile_short,0.45,0.45,7,26,22
triceratops,Triceratops,reptile,9000,0,4,digitigrade,erect,0.20,15,0.0,0.08,0,0.90,20,0.0,0.30,0.20,0.12,0.45,0.30,0.15,dinosaur,0.75,0.75,10,22,40
propalaeotherium,Urpferdchen,mammal,30,0,4,digitigrade,erect,0.45,40,0.05,0.12,0,0.45,45,0.0,0.25,0.27,0.20,0.33,0.33,0.25,mammal_long,0.50,0.55,7,26,18
swan,Schwan,bird,14,1,2,plantigrade,erect,1.60,70,0.30,0.02,15,0.15,15,0.0,0.60,0.60,0.55,0.30,0.50,0.30,bird,0.45,0.60,24,12,7
chameleon,Chamäleon,reptile,1,0,4,plantigrade,crouched,0.10,10,0.0,0.20,0,1.10,60,0.10,0.35,0.30,0.20,0.35,0.30,0.20,reptile_short,0.45,0.60,4,19,45
chamois,Gämse,mammal,37,0,4,unguligrade,erect,0.60,45,0.05,0.06,0,0.10,60,0.0,0.28,0.30,0.35,0.38,0.38,0.40,mammal_long,0.40,0.55,7,19,10
wildebeest,Gnu,mammal,200,0,4,unguligrade,erect,0.60,30,0.05,0.02,0,0.45,75,0.0,0.30,0.33,0.38,0.35,0.37,0.40,mammal_long,0.50,0.60,7,19,16
pig,Schwein,mammal,100,0,4,digitigrade,erect,0.25,15,0.0,0.10,0,0.25,70,0.0,0.22,0.18,0.15,0.28,0.22,0.18,mammal_long,0.45,0.60,7,21,20
kangaroo,Känguru,mammal,50,0,2,plantigrade,crouched,0.35,60,0.0,0.10,40,1.40,30,-0.05,0.20,0.20,0.12,0.45,0.70,0.60,mammal_long,0.35,0.55,7,19,22
tyrannosaurus,Tyrannosaurus,reptile,9000,0,2,digitigrade,erect,0.50,30,0.20,0.05,-5,1.80,5,0.0,0.12,0.07,0.05,0.55,0.50,0.40,dinosaur,0.65,0.60,10,15,38
dromedary,Dromedar,mammal,500,0,4,digitigrade,erect,0.90,30,-0.15,0.05,0,0.40,80,0.0,0.30,0.40,0.35,0.45,0.42,0.38,mammal_long,0.45,0.60,7,19,16
ostrich,Afrikanischer Strauß,bird,120,1,2,digitigrade,erect,1.40,80,0.15,0.02,15,0.20,20,0.0,0.25,0.25,0.20,0.35,0.75,0.70,bird,0.20,0.90,18,14,9
frog,Frosch,amphibian,0.01,0,4,plantigrade,crouched,0.05,0,0,0.20,20,0.10,20,0.0,0.30,0.25,0.30,0.70,0.70,0.90,amphibian,0.45,0.50,1,8,1
crocodile,Krokodil,reptile,500,0,4,plantigrade,sprawling,0.35,0,0,0.02,0,1.40,8,0.0,0.22,0.15,0.15,0.28,0.20,0.22,reptile_long,0.65,0.45,9,17,35
snake,Schlange,reptile,50,0,0,plantigrade,erect,0,0,0,0.0,0,0,0,0.0,0,0,0,0,0,0,snake,0.04,0.03,0,200,0
giraffe,Giraffe,mammal,1200,0,4,unguligrade,erect,1.90,60,0.0,0.05,0,0.60,80,0.0,0.45,0.60,0.55,0.55,0.55,0.60,mammal_long,0.60,0.70,7,19,20
"""

#: Fraction of the straightened limb an animal stands at, per posture.
STAND = {"erect": 0.9, "sprawling": 0.55, "crouched": 0.6}

#: Columns of the produced ``species.csv``.
CSV_COLUMNS = (
    ("name", "german", "class", "weight_kg", "wings", "legs")
    + tuple(f"p{i}{c}" for i in range(10) for c in "xy")
    + ("upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot")
    + ("stance", "posture", "skull", "skull_length", "girth", "cervical", "trunk", "caudal")
    + ("hoof_digits",)
)

#: Hoofed digits of the unguligrade species (the others' column stays empty): the horse is a
#: perissodactyl on digit III alone; buffalo, red deer, chamois, wildebeest and giraffe are
#: artiodactyls on III + IV.
HOOF_DIGITS = {"horse": 1}


def descriptors() -> list[dict[str, str]]:
    """The descriptor table as a list of dicts (strings as written above)."""
    rows = list(csv.reader(io.StringIO(DESCRIPTORS_TEXT.strip())))
    out = []
    for row in rows:
        if len(row) != len(DESCRIPTOR_COLUMNS):
            raise ValueError(
                f"descriptor row {row[0]} has {len(row)} fields, expected {len(DESCRIPTOR_COLUMNS)}"
            )
        out.append(dict(zip(DESCRIPTOR_COLUMNS, row, strict=True)))
    return out


def _dir(angle_deg: float) -> np.ndarray:
    a = np.radians(angle_deg)
    return np.array([np.cos(a), np.sin(a)])


def _curve(p0: np.ndarray, p3: np.ndarray, bend: float) -> np.ndarray:
    """Cubic Bézier from p0 to p3 with both inner points pushed sideways by ``bend`` × chord
    (positive = to the left of the direction p0→p3)."""
    d = p3 - p0
    n = np.array([-d[1], d[0]])
    return np.stack([p0, p0 + d / 3 + bend * n, p0 + 2 * d / 3 + bend * n, p3])


def layout(desc: dict[str, str]) -> dict[str, object]:
    """Turn one descriptor row into a seed-scheme annotation (px, y up, head on the left)."""
    f = {k: float(desc[k]) for k in DESCRIPTOR_COLUMNS[8:22]}
    f["skull_len"] = float(desc["skull_len"])
    f["girth"] = float(desc["girth"])
    legs, stance, posture = int(desc["legs"]), desc["stance"], desc["posture"]
    stand = STAND[posture]
    foot_part = {"plantigrade": 0.1, "digitigrade": 0.7, "unguligrade": 0.9}[stance]
    fore = (f["upper_arm"] + f["lower_arm"] + f["hand"] * foot_part) * stand
    hind = (f["upper_leg"] + f["lower_leg"] + f["foot"] * foot_part) * stand
    drop_s, drop_h = 0.3 * f["girth"], 0.2 * f["girth"]
    # working frame: head to the +x side, y up, B = 1; hip at x = 0
    if legs == 4:
        hip_y = hind + drop_h
        sh_y = fore + drop_s
        dx = np.sqrt(max(1.0 - (sh_y - hip_y) ** 2, 0.25))
        shoulder = np.array([dx, sh_y])
    else:
        if legs == 2:
            hip_y = hind + drop_h
        else:
            hip_y = 0.5 * max(f["girth"], 0.02)
        shoulder = np.array([0.0, hip_y]) + _dir(f["back_slope"])
    hip = np.array([0.0, hip_y])
    back = _curve(hip, shoulder, f["back_arch"])[::-1]  # shoulder -> hip, arch dorsal
    # seed order: neck head->shoulder, back shoulder->hip, tail hip->tip
    if f["neck_len"] > 0:
        head = shoulder + f["neck_len"] * _dir(f["neck_ang"])
        neck = _curve(head, shoulder, -f["neck_bend"])
    else:
        neck = np.repeat(shoulder[None], 4, axis=0)
    if f["tail_len"] > 0:
        tip = hip + f["tail_len"] * _dir(180.0 + f["tail_ang"])
        tail = _curve(hip, tip, -f["tail_bend"])
    else:
        tail = np.repeat(hip[None], 4, axis=0)
    pts = np.concatenate([neck, back[1:], tail[1:]])  # (10, 2)
    # skull: from the neck end forward (or from the shoulder) by skull_len
    head_pt = pts[0]
    skull_end = head_pt + f["skull_len"] * _dir(-20.0)
    feet = []
    if legs >= 2:
        feet.append([hip[0], 0.0])
    if legs == 4:
        feet.append([shoulder[0], 0.0])
    extent = np.concatenate(
        [pts, skull_end[None], np.array(feet).reshape(-1, 2), pts - [0, 0.5 * f["girth"]]]
    )
    lo, hi = extent.min(axis=0), extent.max(axis=0)
    lo[1] = min(lo[1], 0.0)
    size = max(hi[0] - lo[0], hi[1] - lo[1])
    scale = 950.0 / size
    # mirror x so the head is on the left, centre horizontally, bottom at y = 10 px
    px = 500.0 - (pts[:, 0] - 0.5 * (lo[0] + hi[0])) * scale
    py = 10.0 + (pts[:, 1] - lo[1]) * scale
    out: dict[str, object] = {
        k: desc[k] for k in ("name", "german", "class", "weight_kg", "wings", "legs")
    }
    for i in range(10):
        out[f"p{i}x"] = round(float(px[i]), 1)
        out[f"p{i}y"] = round(float(py[i]), 1)
    for k in ("upper_arm", "lower_arm", "hand", "upper_leg", "lower_leg", "foot"):
        out[k] = round(f[k] * scale, 1)
    out.update(
        stance=stance,
        posture=posture,
        skull=desc["skull"],
        skull_length=round(f["skull_len"] * scale, 1),
        girth=f["girth"],
        cervical=desc["cervical"],
        trunk=desc["trunk"],
        caudal=desc["caudal"],
        hoof_digits=HOOF_DIGITS.get(desc["name"], 2) if stance == "unguligrade" else "",
    )
    return out


def write_csv(path: str | Path) -> Path:
    """Lay out every descriptor row and write the dataset CSV (the shipped ``species.csv``)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(CSV_COLUMNS), lineterminator="\n")
    w.writeheader()
    for d in descriptors():
        w.writerow(layout(d))
    p = Path(path)
    p.write_text(buf.getvalue(), encoding="utf-8")
    return p


if __name__ == "__main__":  # pragma: no cover
    print(write_csv(Path(__file__).with_name("species.csv")))
