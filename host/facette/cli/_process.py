"""`facette process DIR -o OUT`: shape, reflectance samples and report from a scan or a
DiLiGenT-style folder."""
import sys


def register(sub):
    from facette.pipeline import OUTPUTS
    from facette.recon import PS_METHODS
    from facette.recon._ps import T_OMBRE, T_RESIDUAL, T_SOURCE, T_SPEC
    from facette.reflect import THETA0_DEG
    p = sub.add_parser("process", help="process a scan or a DiLiGenT-style folder",
                       description=__doc__.splitlines()[0])
    p.add_argument("source", help="scan directory (scan.json, hdr/) or DiLiGenT-style folder")
    p.add_argument("-o", "--out", required=True, help="output directory (created)")
    p.add_argument("--outputs", default=",".join(OUTPUTS),
                   help=f"comma-separated subset of {','.join(OUTPUTS)} (default: all); only the "
                        "stages they need run")
    p.add_argument("--method", default="hierarchical_tautzia2016",
                   choices=list(PS_METHODS),
                   help="photometric stereo (li_alternating: BRDF-aware, the LI model fitted and the "
                        "normals re-estimated against it in alternation)")
    p.add_argument("--init", default="hierarchical_tautzia2016",
                   choices=[m for m in PS_METHODS if m != "li_alternating"],
                   help="initial normals of --method li_alternating (rpca_wu2010 is better on "
                        "photographs of shiny objects, the hierarchy on matte ones)")
    p.add_argument("--integration", default="frankot_chellappa1988",
                   choices=["frankot_chellappa1988", "simchony1990", "least_squares"])
    p.add_argument("--t-ombre", type=float, default=T_OMBRE, help="shadow angle threshold, rad (1.5)")
    p.add_argument("--t-spec", type=float, default=T_SPEC, help="specular variance threshold (0.25)")
    p.add_argument("--t-source", type=float, default=T_SOURCE,
                   help="max |entry| of a triplet's inverse (10)")
    p.add_argument("--t-residual", type=float, default=T_RESIDUAL,
                   help="LS residual under which a pixel skips the hierarchy (0.03; 0 = never)")
    p.add_argument("--theta0", type=float, default=THETA0_DEG, help="hemisphere cell size, deg (3)")
    p.add_argument("--mask", help="mask PNG (non-zero = object)")
    p.add_argument("--pixel-pitch", type=float, help="object-side pixel size in mm (overrides the scan)")
    p.add_argument("--far-light", action="store_true",
                   help="ignore light positions: one direction per light for every pixel")
    p.add_argument("--mesh-step", type=int, help="mesh vertex every N pixels (default: <= ~1e6 vertices)")
    p.add_argument("--ascii-ply", action="store_true", help="write mesh.ply as ASCII")
    p.add_argument("--brdf-model", default="li",
                   help="model fitted for brdf.json: li, cook_torrance, oren_nayar, lambert")
    p.add_argument("--fit-method", default="least_squares", help="least_squares or genetic")
    p.add_argument("--hsh-order", type=int, default=3, choices=(2, 3),
                   help="hemispherical-harmonics order of relight.rti (2: 4 terms, 3: 9 terms)")
    return p


def run(args):
    from facette.pipeline import process
    outputs = [o.strip() for o in args.outputs.split(",") if o.strip()]
    try:
        res = process(args.source, outputs=outputs, out_dir=args.out, method=args.method,
                      integration=args.integration, t_ombre=args.t_ombre, t_spec=args.t_spec,
                      t_source=args.t_source, t_residual=args.t_residual, theta0_deg=args.theta0,
                      mask=args.mask, pixel_pitch_mm=args.pixel_pitch, near_light=not args.far_light,
                      mesh_step=args.mesh_step, ascii_ply=args.ascii_ply,
                      fit_options={"model": args.brdf_model, "method": args.fit_method},
                      hsh_order=args.hsh_order,
                      ps_options={"init": args.init} if args.method == "li_alternating" else None)
    except (ValueError, FileNotFoundError, TypeError) as exc:
        print(f"facette process: {exc}", file=sys.stderr)
        return 2
    h, w = res.normals.shape[:2]
    print(f"{res.inputs.kind} {res.inputs.source}: {len(res.inputs.light_dirs)} lights, {w}x{h} px, "
          f"{int(res.mask.sum())} valid pixels ({res.options['method']})")
    info = res.ps.info
    if "skipped_fraction" in info:
        print(f"  least squares explained {100 * info['skipped_fraction']:.1f} % of the pixels "
              "(hierarchy skipped there)")
    for k, v in res.errors.items():
        print(f"  against truth: {k} = {v:.3f}")
    for k, v in res.fit_errors.items():
        print(f"  relighting against the HDR images: {k} = {v:.4f}")
    print("  times: " + ", ".join(f"{k} {v:.2f} s" for k, v in res.timings.items()))
    if res.brdf is not None:
        print(f"  brdf: {res.brdf}")
    for note in res.notes:
        print(f"  note: {note}")
    for o, path in res.files.items():
        print(f"  wrote {path}")
    return 0
