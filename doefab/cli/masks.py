"""``doefab masks``: export an L-level design as log2 L binary photomask layers (GDSII [+ OASIS]) and verify them.

The number of levels is the design's (design.json ``n_levels``): 16 levels make 4 etch layers (1–4), 8 make 3,
32 make 5 (layers 1–4 and 6; layer 5 is the chrome plate).

Examples:
  doefab masks --design out/designs/streak --out masks/streak --oasis
  doefab masks --verify masks/streak
"""

from __future__ import annotations

import argparse
from pathlib import Path

from doefab.cli._args import design_folder, number, plain_name_arg
from doefab.diekey import DEFAULT_THICKNESS_MM
from doefab.errors import DoefabError
from doefab.io import json_text


def register(sub) -> None:
    p = sub.add_parser("masks", help="export a design as binary mask layers, or --verify a set",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", help="design folder (design.json + levels.npy), a mask set, or a shipped design's "
                                         "name (streak, grating, half-ring)")
    p.add_argument("--out", help="mask-set folder to write (must not exist unless --force)")
    p.add_argument("--verify", metavar="DIR", help="re-check an existing mask set instead of exporting")
    p.add_argument("--name", type=plain_name_arg, default=None,
                   help="base file name, a plain name without '/' (default: the design's task)")
    p.add_argument("--oasis", action="store_true", help="also write OASIS (identical geometry, much smaller)")
    p.add_argument("--die-mm", type=number(float, 1, 300, unit="mm"), default=12.0,
                   help="die size, square, in mm (default 12)")
    p.add_argument("--die-chamfer-mm", type=number(float, 0, 150, unit="mm"), default=None,
                   help="the dicing outline's key: the larger of the two chamfers on the coded half's corners, as "
                        "the holder's die_chamfer_mm (default 2, or a quarter of a die of 4 mm or less; 0: a square "
                        "die)")
    p.add_argument("--substrate-mm", type=number(float, 0.1, 10, unit="mm"), default=DEFAULT_THICKNESS_MM,
                   help=f"the substrate's thickness in mm, as the holder's die_thickness_mm (default "
                        f"{DEFAULT_THICKNESS_MM:g})")
    p.add_argument("--cd-um", type=number(float, 0.1, 1000, unit="µm"), default=None,
                   help="critical dimension in µm (default: the pixel pitch)")
    p.add_argument("--vertex-cap", type=number(int, 5, 8190), default=4000,
                   help="max vertices per polygon (GDSII limit 8190; default 4000)")
    p.add_argument("--align-chain", choices=["chrome", "sequential"], default="chrome",
                   help="every etch mask aligns to the chrome keys, or each to the previous plate (default chrome)")
    p.add_argument("--etch-order", type=int, nargs="+", default=None, metavar="LAYER",
                   help="etch layers in process order, each once (default deepest first: 4 3 2 1 for 16 levels, "
                        "3 2 1 for 8, 6 4 3 2 1 for 32)")
    p.add_argument("--resist", choices=["positive", "negative"], default="positive",
                   help="resist tone (default positive: etch plates dark field, clear inside their polygons)")
    p.add_argument("--pattern-faces", choices=["lens", "scene"], default="lens",
                   help="which way the etched face points when mounted (default lens: the layout is the design "
                        "mirrored in x)")
    p.add_argument("--no-klayout", action="store_true", help="skip the KLayout cross-check")
    p.add_argument("--force", action="store_true", help="replace an existing mask-set folder")
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab.fabrication.export import MaskOptions, export_masks
    from doefab.fabrication.verify import verify_mask_set

    if args.verify:
        if args.design or args.out:
            raise DoefabError("--verify DIR checks an existing set; --design/--out export one: give one or the other")
        report = verify_mask_set(args.verify, use_klayout=not args.no_klayout)
        print(json_text(report, indent=1))
        files = " and ".join([report["gds"]] + ([report["oasis"]["file"]] if "oasis" in report else []))
        print(f"{args.verify}: verified {files} (0 mismatched pixels on every etch layer, nothing outside the pixel "
              f"grid; chrome, marks and die outline where manifest.json places them within "
              f"{report['marks']['tolerance_nm']} nm; geometry only on the layers manifest.json lists)")
        return 0
    if not args.design or not args.out:
        raise DoefabError("give --design DIR and --out DIR (or --verify DIR)")
    from doefab.cli._output import claim_output
    from doefab.fabrication.layers import etch_layer
    from doefab.fabrication.process import mask_count

    ddir, design = design_folder(args.design)  # a folder, a mask set or a shipped design's name
    layers = [etch_layer(b) for b in range(mask_count(design.n_levels))]
    if args.etch_order is not None and sorted(args.etch_order) != layers:
        raise DoefabError(f"--etch-order {' '.join(map(str, args.etch_order))} must name each etch layer of this "
                          f"{design.n_levels}-level design ({' '.join(map(str, layers))}) once, e.g. --etch-order "
                          f"{' '.join(map(str, layers[::-1]))}")
    if args.die_chamfer_mm is not None and args.die_chamfer_mm >= args.die_mm / 2:
        raise DoefabError(f"--die-chamfer-mm {args.die_chamfer_mm:g} must be below half the die (--die-mm "
                          f"{args.die_mm:g}): give a smaller chamfer, e.g. {args.die_mm / 4:g}")
    claim_output(args, "masks", replace=args.force)  # validates --out before any work
    opts = MaskOptions(name=args.name or design.task.replace("-", ""), oasis=args.oasis, die_m=args.die_mm * 1e-3,
                       **({} if args.die_chamfer_mm is None else {"die_chamfer_m": args.die_chamfer_mm * 1e-3}),
                       cd_m=None if args.cd_um is None else args.cd_um * 1e-6, vertex_cap=args.vertex_cap,
                       substrate_thickness_m=args.substrate_mm * 1e-3,
                       align_chain=args.align_chain, resist=args.resist,
                       etch_order=None if args.etch_order is None else tuple(args.etch_order),
                       use_klayout=not args.no_klayout, pattern_faces=args.pattern_faces)
    report = export_masks(design, Path(args.out), opts, design_dir=ddir, force=args.force)
    for lay, st in report["layers"].items():
        corners = report.get("width_space", {}).get(str(lay), {}).get("corner_contacts")
        print(f"layer {lay}: {st['polygons']} polygons, {st['vertices']} vertices (max {st['max_vertices']}), "
              f"{st['mismatched_pixels_gdstk']} mismatched pixels"
              + ("" if corners is None else f", {corners} corner contacts"))
    if any(w.get("corner_contacts") for w in report.get("width_space", {}).values()):
        print("corner contacts: etched pixels that touch only at a corner, where a Euclidean width/space check finds "
              "zero width (they may print pinched or bridged); report.json lists the first of each layer (µm)")
    sizes = ", ".join(f"{k} {v / 1e6:.1f} MB" for k, v in report["file_bytes"].items())
    print(f"wrote and verified {args.out} ({sizes}) in {report['export_seconds']:.1f} s")
    return 0
