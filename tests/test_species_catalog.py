"""The species catalog: every file loads, its numbers agree with the published facts of
docs/biomechanics.md, and broken files and names are rejected clearly."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from habitsim.cli import main
from habitsim.errors import (
    HabitsimError,
    SpeciesFileError,
    UnknownSpeciesError,
)
from habitsim.skeleton import standing_leg_angles
from habitsim.species import (
    POSTURES,
    all_species,
    held_out_species,
    load_species,
    load_species_file,
    species_names,
    training_species,
)

CATALOG = Path(__file__).resolve().parents[1] / "habitsim" / "catalog"
DOG = CATALOG / "dog.toml"

# Hip heights [m] of docs/biomechanics.md, "Body sizes" table (Alexander & Jayes 1983 and
# the species sources cited in each TOML file).
REFERENCE_HIP_HEIGHT = {
    "cat": 0.25,
    "rabbit": 0.15,
    "fox": 0.35,
    "dog": 0.55,
    "wolf": 0.75,
    "goat": 0.7,
    "deer": 0.9,
    "pig": 0.7,
    "tiger": 0.95,
    "bear": 1.0,
    "zebra": 1.3,
    "horse": 1.5,
    "moose": 1.8,
    "camel": 1.9,
    "cow": 1.3,
    "giraffe": 3.0,
    "elephant": 2.5,
}
# Reference masses [kg] of the same table (ranges given there as (lo, hi)).
REFERENCE_MASS = {
    "cat": (4.5, 4.5),
    "rabbit": (2, 2),
    "fox": (7, 7),
    "dog": (25, 25),
    "wolf": (40, 40),
    "goat": (50, 70),
    "deer": (70, 70),
    "pig": (100, 100),
    "tiger": (190, 220),
    "bear": (250, 250),
    "zebra": (300, 300),
    "horse": (500, 500),
    "moose": (450, 450),
    "camel": (500, 500),
    "cow": (600, 600),
    "giraffe": (900, 900),
    "elephant": (3500, 3500),
}

# Footfall phases (LH = 0) per gait type, docs/biomechanics.md "Footfall patterns and duty
# factors" table (Hildebrand).
# A lateral-sequence walk may shift LF toward LH (pace-like walks of camels and giraffes),
# which the 0.1 tolerance plus the wider WALK_LF_RANGE allow.
GAIT_PHASES = {
    "walk": {"LF": 0.25, "RH": 0.5, "RF": 0.75},
    "amble": {"LF": 0.25, "RH": 0.5, "RF": 0.75},
    "trot": {"LF": 0.5, "RH": 0.5, "RF": 0.0},
    "pace": {"LF": 0.0, "RH": 0.5, "RF": 0.5},
    "half_bound": {"LF": 0.5, "RH": 0.05, "RF": 0.55},
    "bound": {"LF": 0.5, "RH": 0.05, "RF": 0.55},
    "transverse_gallop": {"LF": 0.5, "RH": 0.1, "RF": 0.6},
    "rotary_gallop": {"LF": 0.6, "RH": 0.1, "RF": 0.5},
    # Not in the table: three-beat canter, LH first, then the diagonal pair RH + LF, then RF.
    "canter": {"LF": 0.25, "RH": 0.25, "RF": 0.45},
}
PHASE_TOL = 0.1
WALK_LF_RANGE = (0.1, 0.35)  # lateral-sequence walks, pace-like (camel, giraffe) to even

EXPECTED_HELD_OUT = {
    "wolf": "dog",
    "zebra": "horse",
    "tiger": "cat",
    "moose": "deer",
    "giraffe": "camel",
}


def _phase_diff(a: float, b: float) -> float:
    d = abs(a - b) % 1.0
    return min(d, 1.0 - d)


@pytest.fixture(scope="module")
def catalog():
    return {sp.name: sp for sp in all_species()}


# ------------------------------------------------------------------ contents


def test_catalog_size_and_names(catalog):
    assert len(catalog) >= 17
    assert set(REFERENCE_HIP_HEIGHT) <= set(catalog)
    assert species_names() == sorted(catalog)


@pytest.mark.parametrize("path", sorted(CATALOG.glob("*.toml")), ids=lambda p: p.stem)
def test_every_file_loads_and_file_name_matches(path):
    sp = load_species_file(path)
    assert sp.name == path.stem
    assert len(sp.sources) >= 2
    assert 15 <= len(sp.description.split()) <= 160
    assert 3 <= len(re.findall(r"[.!?](\s|$)", sp.description)) <= 6


@pytest.mark.parametrize("name", sorted(REFERENCE_HIP_HEIGHT))
def test_derived_hip_height_matches_reference(catalog, name):
    sp = catalog[name]
    ref = REFERENCE_HIP_HEIGHT[name]
    assert abs(sp.hip_height - ref) <= 0.15 * ref, f"{name}: hip {sp.hip_height:.3f} m vs {ref} m"


@pytest.mark.parametrize("name", sorted(REFERENCE_MASS))
def test_mass_matches_reference(catalog, name):
    lo, hi = REFERENCE_MASS[name]
    assert 0.85 * lo <= catalog[name].mass_kg <= 1.15 * hi


def test_descriptions_differ(catalog):
    texts = [sp.description for sp in catalog.values()]
    assert len(set(texts)) == len(texts)


def test_held_out_and_outliers(catalog):
    held = held_out_species()
    assert len(held) >= 4
    for sp in held:
        assert sp.cousin in catalog, f"{sp.name}: cousin {sp.cousin!r} is not in the catalog"
        assert not catalog[sp.cousin].held_out, f"{sp.name}: cousin {sp.cousin} is held out too"
    for name, cousin in EXPECTED_HELD_OUT.items():
        assert catalog[name].held_out and catalog[name].cousin == cousin
    outliers = [sp for sp in catalog.values() if sp.outlier]
    assert outliers and all(sp.held_out for sp in outliers)
    assert catalog["giraffe"].outlier
    assert {s.name for s in training_species()} == {n for n, s in catalog.items() if not s.held_out}
    for sp in catalog.values():
        if sp.name not in EXPECTED_HELD_OUT:
            assert not sp.held_out and not sp.outlier, sp.name


def test_posture_classes(catalog):
    assert {sp.posture for sp in catalog.values()} == set(POSTURES)
    assert catalog["cat"].posture == "crouched_digitigrade"
    assert catalog["bear"].posture == "plantigrade"
    assert catalog["elephant"].posture == "columnar"
    for name in ("horse", "cow", "zebra", "deer", "moose", "goat", "pig"):
        assert catalog[name].posture == "unguligrade", name


def test_gait_repertoires(catalog):
    pacers = [sp.name for sp in catalog.values() if "pace" in sp.gaits and "trot" not in sp.gaits]
    assert {"camel", "giraffe"} <= set(pacers)
    bounders = [sp.name for sp in catalog.values() if {"bound", "half_bound"} & set(sp.gaits)]
    assert "rabbit" in bounders
    assert set(catalog["horse"].gaits) == {"walk", "trot", "canter", "transverse_gallop"}
    assert set(catalog["elephant"].gaits) == {"walk", "amble"}
    assert "amble" in catalog["bear"].gaits and "trot" not in catalog["bear"].gaits
    assert "trot" in catalog["moose"].gaits
    for sp in catalog.values():
        assert "walk" in sp.gaits


def test_elephant_never_has_an_aerial_phase(catalog):
    el = catalog["elephant"]
    for g, gh in el.gaits.items():
        assert gh.duty_factor[0] >= 0.4, g
    assert max(gh.froude[1] for gh in el.gaits.values()) <= 1.1


def test_footfall_phases_match_gait_table(catalog):
    for sp in catalog.values():
        for g, gh in sp.gaits.items():
            assert gh.footfall["LH"] == 0.0
            for foot, ref in GAIT_PHASES[g].items():
                assert _phase_diff(gh.footfall[foot], ref) <= PHASE_TOL + 1e-9, (sp.name, g, foot)
            if g in ("walk", "amble"):
                lo, hi = WALK_LF_RANGE
                assert lo <= gh.footfall["LF"] <= hi, (sp.name, g)


def test_duty_factors_and_froude_bands(catalog):
    for sp in catalog.values():
        for g, gh in sp.gaits.items():
            dlo, dhi = gh.duty_factor
            flo, fhi = gh.froude
            assert dhi - dlo >= 0.08 - 1e-9, (sp.name, g)
            assert fhi - flo >= 0.2 - 1e-9, (sp.name, g)
            assert fhi <= 6.0 + 1e-9, (sp.name, g)
            if g == "walk":
                assert 0.55 <= dlo and dhi <= 0.8 and fhi <= 0.5, sp.name
            elif g in ("trot", "pace"):
                assert 0.35 <= dlo and dhi <= 0.55, (sp.name, g)
                assert 0.4 <= flo and fhi <= 2.5, (sp.name, g)
            elif g == "amble":
                assert 0.4 <= dlo and dhi <= 0.6 and fhi <= 1.5, sp.name
            elif g in ("rotary_gallop", "transverse_gallop", "bound"):
                assert 0.2 <= dlo and dhi <= 0.4, (sp.name, g)
                # Giraffes gallop at unusually low Froude numbers (Basu et al. 2019, PeerJ).
                assert flo >= (1.0 if sp.outlier else 2.0), (sp.name, g)
        # Faster gaits start at higher Froude numbers than the walk and use shorter stances.
        walk = sp.gaits["walk"]
        for g, gh in sp.gaits.items():
            if g != "walk":
                assert gh.froude[0] >= walk.froude[0] and gh.froude[1] > walk.froude[1], (
                    sp.name,
                    g,
                )
                assert gh.duty_factor[1] < walk.duty_factor[1], (sp.name, g)


def test_posture_is_plausible(catalog):
    for sp in catalog.values():
        # toe roughly under the hip and the shoulder
        for limb, length in (("hind", sp.hind_leg_length), ("fore", sp.fore_leg_length)):
            dx = sum(
                sp.segments[f"{limb}_{k}"] * math.sin(sp.inclinations[f"{limb}_{k}"])
                for k in ("upper", "lower", "foot")
            )
            assert abs(dx) <= 0.25 * length, (sp.name, limb, dx / length)
        assert abs(math.degrees(sp.trunk_pitch)) < 35.0, sp.name
    # large animals stand on near-vertical legs, small crouched ones on inclined segments
    for name in ("horse", "cow", "elephant"):
        sp = catalog[name]
        upright = [
            abs(math.degrees(sp.inclinations[f"{limb}_{k}"])) < 20.0
            for limb in ("fore", "hind")
            for k in ("upper", "lower", "foot")
        ]
        assert sum(upright) >= 4, name
    for name in ("cat", "rabbit"):
        sp = catalog[name]
        assert all(
            abs(math.degrees(sp.inclinations[f"hind_{k}"])) >= 20.0
            for k in ("upper", "lower", "foot")
        )
    assert 60.0 <= math.degrees(catalog["bear"].inclinations["hind_foot"]) <= 75.0
    # the giraffe's fore legs are longer and its withers far higher than the sacrum
    gi = catalog["giraffe"]
    assert gi.fore_leg_length >= gi.hind_leg_length * 0.95
    assert (
        gi.shoulder_height + gi.segments["fore_girdle"] > gi.hip_height + gi.segments["hind_girdle"]
    )
    assert math.degrees(gi.trunk_pitch) > 8.0
    # crouched small animals have a shorter hip height relative to their leg length
    ratio = {n: s.hip_height / s.leg_length for n, s in catalog.items()}
    assert ratio["cat"] < ratio["horse"] and ratio["rabbit"] < ratio["cow"]


def test_joint_limits_leave_room_to_move(catalog):
    for sp in catalog.values():
        for role, angle in standing_leg_angles(sp).items():
            lo, hi = sp.joint_limits[role]
            need = math.radians(
                20.0
                if ("girdle" in role or role.split("_")[0] in ("neck", "head", "tail"))
                else 35.0
            )
            if role == "tail_pitch":
                need = math.radians(10.0)  # hanging tails may rest near their lower limit
            assert angle - lo >= need - 1e-6 and hi - angle >= need - 1e-6, (sp.name, role)


def test_girths_and_habits(catalog):
    for sp in catalog.values():
        g = sp.girths
        assert g["trunk"] == max(g.values()), sp.name
        assert g["hind_upper"] > g["hind_lower"] >= g["hind_foot"] * 0.9, sp.name
        # girth vs mass: a water-density trunk cylinder weighs 40-110 % of the body
        vol = g["trunk"] ** 2 / (4 * math.pi) * (sp.segments["trunk"] + sp.segments["hind_girdle"])
        assert 0.4 <= vol * 1000.0 / sp.mass_kg <= 1.1, (sp.name, vol * 1000.0 / sp.mass_kg)
        h = sp.habits
        assert 3.0 <= h.stride_frequency_coeff_hz <= 6.0
        assert 0.08 <= h.swing_height <= 0.2
        assert 0.3 <= h.trunk_sway <= 0.8
    spine = {n: math.degrees(s.habits.spine_flex) for n, s in catalog.items()}
    for flexible in ("cat", "dog", "rabbit"):
        assert 10.0 <= spine[flexible] <= 20.0
    for stiff in ("horse", "cow", "elephant", "camel"):
        assert 2.0 <= spine[stiff] <= 5.0
    assert catalog["horse"].habits.head_bob > catalog["dog"].habits.head_bob


def test_heavier_species_step_slower(catalog):
    """Heglund et al. 1974: f = c M^-0.14; with c near 4.5 the heavier of two species whose
    masses differ at least two-fold has the lower characteristic stride frequency."""
    freq = {n: s.habits.stride_frequency_coeff_hz * s.mass_kg**-0.14 for n, s in catalog.items()}
    for a in catalog.values():
        for b in catalog.values():
            if b.mass_kg >= 2.0 * a.mass_kg:
                assert freq[b.name] < freq[a.name], (a.name, b.name)


# ------------------------------------------------------------------ bad files and names


def _broken(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    text = DOG.read_text(encoding="utf-8")
    assert old in text, old
    p = tmp_path / "broken.toml"
    p.write_text(text.replace(old, new, count), encoding="utf-8")
    return p


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("mass_kg = 25.0\n", "", "mass_kg"),
        ("hind_lower = 0.22\n", "", "hind_lower"),
        ('class = "digitigrade"', 'class = "tiptoe"', "posture class"),
        (
            "hind_lower_flex_deg = [0.0, 150.0]",
            "hind_lower_flex_deg = [0.0, 30.0]",
            "hind_lower_flex",
        ),
        ("held_out = false", "held_out = true", "cousin"),
        ("[gaits.trot]", "[gaits.gallump]", "unknown gait"),
        (
            "footfall = { LH = 0.0, LF = 0.5, RH = 0.5, RF = 0.0 }",
            "footfall = { LH = 0.0, LF = 0.5, RH = 0.5 }",
            "footfall",
        ),
        ("duty_factor = [0.35, 0.50]", "duty_factor = [0.50, 0.35]", "min"),
        ("[gaits.walk]", "[gaits.amble]", "walk"),
        ('name = "dog"', 'name = "Big Dog"', "lower-case"),
    ],
    ids=[
        "missing-mass",
        "missing-segment",
        "bad-posture",
        "standing-angle-outside-limits",
        "held-out-without-cousin",
        "unknown-gait",
        "missing-foot",
        "inverted-range",
        "no-walk",
        "bad-name",
    ],
)
def test_bad_species_files_are_rejected(tmp_path, old, new, match):
    with pytest.raises(SpeciesFileError, match=match):
        load_species_file(_broken(tmp_path, old, new))


def test_unreadable_toml_is_rejected(tmp_path):
    p = tmp_path / "garbage.toml"
    p.write_text("name = [unclosed\n", encoding="utf-8")
    with pytest.raises(SpeciesFileError):
        load_species_file(p)
    with pytest.raises(SpeciesFileError):
        load_species_file(tmp_path / "missing.toml")


def test_dog_copy_loads(tmp_path):
    sp = load_species_file(_broken(tmp_path, "mass_kg = 25.0", "mass_kg = 26.0"))
    assert sp.mass_kg == 26.0


def test_unknown_species_name_lists_known_names():
    with pytest.raises(UnknownSpeciesError) as ei:
        load_species("unicorn")
    msg = str(ei.value)
    assert "unicorn" in msg
    for name in ("dog", "horse", "elephant", "giraffe"):
        assert name in msg
    assert load_species("horse") is load_species(load_species("horse"))


# ------------------------------------------------------------------ CLI


def test_cli_species_list_json(capsys, catalog):
    assert main(["species", "list", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert isinstance(data, list) and len(data) == len(catalog)
    keys = {
        "name",
        "common_name",
        "mass_kg",
        "hip_height_m",
        "leg_length_m",
        "posture",
        "held_out",
        "cousin",
        "outlier",
        "gaits",
    }
    for row in data:
        assert keys <= set(row)
        sp = catalog[row["name"]]
        assert row["mass_kg"] == sp.mass_kg
        assert row["hip_height_m"] == pytest.approx(sp.hip_height, abs=1e-3)
        assert row["held_out"] == sp.held_out
    assert [r["name"] for r in data] == sorted(catalog)


def test_cli_species_list_table(capsys, catalog):
    assert main(["species", "list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "name" in lines[0] and "posture" in lines[0] and "hip" in lines[0]
    assert len(lines) == len(catalog) + 2  # header, rule, one row per species
    widths = {len(line.rstrip()) for line in lines[2:]}
    assert max(widths) <= len(lines[1])  # aligned under the rule line
    giraffe = next(line for line in lines if line.startswith("giraffe "))
    assert "camel" in giraffe and "outlier" in giraffe and "2.7" in giraffe


def test_cli_species_show(capsys):
    assert main(["species", "show", "elephant"]) == 0
    out = capsys.readouterr().out
    assert "columnar" in out and "amble" in out and "Hutchinson" in out
    assert main(["species", "show", "horse", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["name"] == "horse" and "canter" in d["gait_habits"] and d["description"]
    assert d["segments_m"]["hind_upper"] > 0 and "hind_lower_flex" in d["joint_limits_deg"]


def test_cli_errors_exit_2(capsys):
    assert main(["species", "show", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown species 'nosuch'; known: ") and "dog" in err
    with pytest.raises(SystemExit) as ei:
        main(["species", "frobnicate"])
    assert ei.value.code == 2


def _species_toml(tmp_path: Path, old: str, new: str, top: str = "") -> Path:
    """The dog's species file with ``old`` replaced by ``new`` (every time) and ``top``
    put first (top-level keys)."""
    from habitsim.species import load_species

    text = load_species("dog").path.read_text(encoding="utf-8")
    assert old in text
    p = tmp_path / "dog.toml"
    p.write_text(top + "\n" + text.replace(old, new), encoding="utf-8")
    return p


@pytest.mark.parametrize(
    "old, new, top, match",
    [
        ("[posture]", "[xposture]", "posture = 5", "posture must be a table"),
        ("[gaits.", "[xgaits.", 'gaits = "x"', "gaits must be a table"),
        ("[segments]", "[xsegments]", "segments = [1, 2]", "segments must be a table"),
        ("mass_kg = ", "mass_kg = 1e300 # ", "", "within"),
        ("mass_kg = ", "mass_kg = 100000000000000000000 # ", "", "within"),
    ],
    ids=["posture_int", "gaits_str", "segments_list", "mass_huge", "mass_bigint"],
)
def test_species_toml_wrong_types(tmp_path: Path, old: str, new: str, top: str, match: str):
    from habitsim.errors import SpeciesFileError
    from habitsim.species import load_species_file

    with pytest.raises(SpeciesFileError, match=match):
        load_species_file(_species_toml(tmp_path, old, new, top))


def test_species_cli_bad_file_exit_2(tmp_path: Path, capsys) -> None:
    from habitsim.species import load_species_file

    p = _species_toml(tmp_path, "[posture]", "[xposture]", "posture = 5")
    with pytest.raises(HabitsimError):
        load_species_file(p)
