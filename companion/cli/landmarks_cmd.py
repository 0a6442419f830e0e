"""``companion landmarks``: import, export, list, show, score, select and sync landmarks."""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from companion.core.landmark import Area, Landmark, parse_area
from companion.core.map_file import landmark_to_feature, write_map
from companion.errors import CompanionError, InputError
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.geodesy import LocalFrame, corners_ned, pick_one
from companion.landmarks.repository import LandmarkRepository, import_map
from companion.landmarks.scores import VrScorer, evaluate, tracker_vr_scorer
from companion.landmarks.selection import Selection, busy_zones, read_busy_zones
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository
from companion.landmarks.sync import open_repository, select_area, sync_practical_map
from companion.settings import Settings

AREA_HELP = "bbox:MIN_LON,MIN_LAT,MAX_LON,MAX_LAT or circle:LAT,LON,RADIUS_M"


def _area(text: str) -> Area:
    try:
        return parse_area(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _selection_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--area", type=_area, required=True, help=AREA_HELP)
    parser.add_argument("--min-spacing", type=float, metavar="M",
                        help="minimum distance between landmarks (default: config)")
    parser.add_argument("--max", type=int, metavar="N", dest="max_count",
                        help="maximum number of landmarks (default: config)")
    parser.add_argument("--include-candidates", action="store_true", default=None,
                        help="also use landmarks not yet admitted (status candidate)")
    parser.add_argument("--busy-zones", type=Path, metavar="FILE",
                        help="GeoJSON polygons to avoid (added to the configured ones)")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``companion landmarks``."""
    parser = sub.add_parser(
        "landmarks", help="the landmark database: import, export, list, score, select, sync",
        description="Manage the landmark database (SQLite on board, PostGIS in the cloud).")
    parser.add_argument("--db", help="database: a SQLite file or a postgresql:// URL "
                        "(default: landmarks.db_path)")
    actions = parser.add_subparsers(dest="landmarks_action", metavar="ACTION", required=True)
    imp = actions.add_parser("import", help="import a GeoJSON landmark map (all or nothing)")
    imp.add_argument("file", type=Path)
    imp.add_argument("--replace", action="store_true", help="overwrite landmarks with equal ids")
    exp = actions.add_parser("export", help="export every landmark as a GeoJSON map")
    exp.add_argument("file", type=Path)
    exp.add_argument("--embed-appearance", action="store_true",
                     help="images as data URIs instead of files beside the map")
    lst = actions.add_parser("list", help="list landmarks (of an area)")
    lst.add_argument("--area", type=_area, help=AREA_HELP)
    lst.add_argument("--json", action="store_true", help="GeoJSON features, one JSON document")
    show = actions.add_parser("show", help="one landmark by id or name")
    show.add_argument("id")
    show.add_argument("--origin", metavar="LAT,LON,ALT_M",
                      help="also print its centre and corners in NED about this origin")
    show.add_argument("--json", action="store_true")
    score = actions.add_parser("score", help="measure admission scores; admit or reject")
    score.add_argument("--restatus", action="store_true",
                       help="re-decide approved/rejected landmarks too, not only candidates")
    sel = actions.add_parser("select", help="the practical map of an area, with reasons")
    _selection_options(sel)
    sel.add_argument("--json", action="store_true")
    syn = actions.add_parser("sync", help="pull an area's practical map into the --db database")
    syn.add_argument("--from", dest="source", required=True, metavar="URL",
                     help="source repository: postgresql://... or a SQLite file")
    _selection_options(syn)
    parser.set_defaults(handler=run)


def _config(settings: Settings) -> LandmarksConfig:
    config = getattr(settings, "landmarks", None)
    return config if isinstance(config, LandmarksConfig) else LandmarksConfig()


#: The actions that may create the ``--db`` database; every other one needs it to exist.
_CREATES = frozenset({"import", "sync"})


def run(args: argparse.Namespace, settings: Settings) -> int:
    """Do one landmarks action."""
    config = _config(settings)
    location = args.db or config.db_path
    if args.landmarks_action == "sync":  # a typo in --from must not leave an empty --db
        open_repository(args.source).close()
    repo = open_repository(location, create=args.landmarks_action in _CREATES)
    try:
        return _ACTIONS[args.landmarks_action](args, repo, config)
    except sqlite3.Error as err:  # read-only file, full disk: one line naming the database
        raise CompanionError(f"{location}: landmark database: {err}") from None
    finally:
        repo.close()


def _import(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    n = import_map(repo, args.file, replace=args.replace)
    print(f"imported {n} landmarks from {args.file} ({repo.count()} in the database)")
    return 0


def _export(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    n = write_map(args.file, repo.iter_all(), embed_appearance=args.embed_appearance)
    print(f"exported {n} landmarks to {args.file}")
    return 0


def _row(lm: Landmark) -> str:
    impact = "-" if lm.scores.impact is None else f"{lm.scores.impact:.2f}"
    return (f"{lm.id:<16} {lm.status:<9} {lm.category:<10} {lm.lat_deg:11.7f} "
            f"{lm.lon_deg:12.7f} {lm.alt_m:7.1f} {impact:>6}  {lm.name}")


_HEADER = (f"{'id':<16} {'status':<9} {'category':<10} {'lat_deg':>11} {'lon_deg':>12} "
           f"{'alt_m':>7} {'impact':>6}  name")


def _list(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    lms = (repo.query_area(args.area) if args.area
           else list(repo.iter_all(with_appearance=False)))
    if args.json:
        json.dump([landmark_to_feature(lm, None) for lm in lms], sys.stdout)
        print()
        return 0
    print(_HEADER)
    for lm in lms:
        print(_row(lm))
    print(f"{len(lms)} landmarks")
    return 0


def _find(repo: LandmarkRepository, key: str) -> Landmark:
    by_id = repo.get(key)
    return pick_one(key, by_id, [] if by_id is not None else repo.find_by_name(key))


def _show(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    lm = _find(repo, args.id)
    doc: dict[str, Any] = landmark_to_feature(lm, None)
    doc["properties"]["status_reason"] = lm.status_reason
    if lm.appearance is not None:
        a = lm.appearance
        doc["appearance"] = {"media_type": a.media_type, "bytes": len(a.data),
                             "box_px": list(a.box_px) if a.box_px else None}
    if args.origin:
        try:
            frame = LocalFrame(*(float(x) for x in args.origin.split(",")))
        except (TypeError, ValueError) as err:
            raise InputError(f"--origin {args.origin!r}: expected LAT,LON,ALT_M ({err})") from None
        corners = corners_ned(lm, frame)
        doc["ned_m"] = {"centre": corners.mean(axis=0).round(3).tolist(),
                        "corners": corners.round(3).tolist()}
    if args.json:
        print(json.dumps(doc))
    else:
        print(json.dumps(doc, indent=2))
    return 0


def _scorer() -> VrScorer | None:
    try:
        return tracker_vr_scorer()
    except CompanionError as err:
        print(f"warning: {err}; keeping declared distinctiveness", file=sys.stderr)
        return None


def _score(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    scorer = _scorer()
    updates = [evaluate(lm, config, scorer, restatus=args.restatus) for lm in repo.iter_all()]
    repo.update_scores(updates)
    counts = Counter(u.status for u in updates)
    print(f"scored {len(updates)} landmarks: " + ", ".join(
        f"{counts[s]} {s}" for s in ("approved", "rejected", "candidate")))
    return 0


def _zones(args: argparse.Namespace, config: LandmarksConfig) -> list[Any]:
    zones = busy_zones(config)
    if args.busy_zones:
        zones += read_busy_zones(args.busy_zones)
    return zones


def _print_selection(sel: Selection, as_json: bool) -> None:
    if as_json:
        json.dump({"selected": [landmark_to_feature(lm, None) for lm in sel.landmarks],
                   "left_out": [{"id": lo.id, "kind": lo.kind, "reason": lo.reason}
                                for lo in sel.left_out],
                   "total_impact": sel.total_impact}, sys.stdout)
        print()
        return
    print(_HEADER)
    for lm in sel.landmarks:
        print(_row(lm))
    print(f"selected {len(sel.ids)} landmarks, total impact {sel.total_impact:.2f}; "
          f"left out {len(sel.left_out)}:")
    for lo in sel.left_out:
        print(f"  {lo.id}: {lo.reason}")


def _select(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    sel = select_area(repo, args.area, config, _zones(args, config),
                      min_spacing_m=args.min_spacing, max_count=args.max_count,
                      include_candidates=args.include_candidates)
    _print_selection(sel, args.json)
    return 0


def _sync(args: argparse.Namespace, repo: LandmarkRepository, config: LandmarksConfig) -> int:
    if not isinstance(repo, SqliteLandmarkRepository):
        raise InputError("sync: --db must be the on-board SQLite file")
    source = open_repository(args.source)
    try:
        sel = sync_practical_map(source, repo, args.area, config, _zones(args, config),
                                 min_spacing_m=args.min_spacing, max_count=args.max_count,
                                 include_candidates=args.include_candidates)
    finally:
        source.close()
    print(f"synced {len(sel.ids)} landmarks (total impact {sel.total_impact:.2f}, "
          f"{len(sel.left_out)} left out) into {repo.path}; {repo.count()} in the database")
    return 0


_ACTIONS = {"import": _import, "export": _export, "list": _list, "show": _show,
            "score": _score, "select": _select, "sync": _sync}
