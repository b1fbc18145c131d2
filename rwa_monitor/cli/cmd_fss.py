"""``rwa-monitor fss build|train|evaluate``: labelled FSS data sets and the classifier."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from rwa_monitor.core.fss.classify import detection_matrix, train_model
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.atomic import write_text_atomic
from rwa_monitor.telemetry.fss_model import save_model

DEFAULT_DATASET = 'data/generated/fss'


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``fss`` with its three sub-commands."""
    parser = subparsers.add_parser(
        'fss', help='FSS window diagnoser: build data sets, train, evaluate',
        description='Labelled windows for the FSS window diagnoser (docs/fss.md).')
    sub = parser.add_subparsers(dest='fss_command', metavar='ACTION', required=True)
    build = sub.add_parser('build', help='write a seeded labelled data set')
    build.add_argument('dataset', nargs='?', default=DEFAULT_DATASET,
                       help=f'output directory (default {DEFAULT_DATASET}, gitignored)')
    build.add_argument('--per-status', type=int, default=50,
                       help='windows per status (5 statuses; default 50)')
    build.add_argument('--samples', type=int, default=80_000,
                       help='samples per window at 10 Hz (default 80000)')
    build.add_argument('--seed', type=int, default=0)
    build.add_argument('--anomalies', choices=('realistic', 'legacy'), default='realistic',
                       help='anomaly sizes: x1.1-x3 of the wheel nominal, with a nominal '
                            'reference window per window (default), or the first bench '
                            '2.5-3x (docs/fss.md)')
    build.set_defaults(func=_build)
    train = sub.add_parser('train', help='train the SVMs on a data set')
    train.add_argument('dataset')
    train.add_argument('-o', '--output', required=True, help='model file (JSON)')
    train.add_argument('--bins', type=int, default=20, help='histogram bins (default 20)')
    train.add_argument('--c', type=float, default=1.0, help='SVM C (default 1.0)')
    train.add_argument('--use', choices=('levels', 'jumps', 'both'), default='both',
                       help='FSS histograms of levels (paper), of jumps, or both (default)')
    train.add_argument('--train-fraction', type=float, default=1.0,
                       help='random fraction of the windows used (default all)')
    train.add_argument('--seed', type=int, default=0, help='seed of the split')
    train.set_defaults(func=_train)
    evaluate = sub.add_parser('evaluate', help='detection matrix of a model on a data set')
    evaluate.add_argument('dataset')
    evaluate.add_argument('--model', default=None, help='model file (default: shipped)')
    evaluate.add_argument('-o', '--output', default=None, help='write the matrix as JSON')
    evaluate.set_defaults(func=_evaluate)


def _progress(done: int, total: int) -> None:
    if done == total or done % 25 == 0:
        print(f'  {done}/{total} windows', file=sys.stderr)


def _build(args: argparse.Namespace) -> int:
    from rwa_monitor.sim.fss import build_dataset
    try:
        manifest = build_dataset(args.dataset, per_status=args.per_status, seed=args.seed,
                                 n_samples=args.samples, anomalies=args.anomalies)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    print(f'{len(manifest["windows"])} windows written to {args.dataset}')
    return 0


def _items(dataset: str) -> list[dict]:
    from rwa_monitor.sim.fss import dataset_extractions
    try:
        return dataset_extractions(dataset, progress=_progress)
    except (ValueError, OSError) as err:
        raise ConfigError(str(err)) from None


def _train(args: argparse.Namespace) -> int:
    items = _items(args.dataset)
    if not 0.0 < args.train_fraction <= 1.0:
        raise ConfigError('--train-fraction must be in (0, 1]')
    rng = np.random.default_rng(args.seed)
    n_train = max(1, int(round(args.train_fraction * len(items))))
    chosen = [items[i] for i in sorted(rng.permutation(len(items))[:n_train])]
    # Windows with a nominal reference (realistic data sets) train on features relative
    # to it, the way a calibrated wheel is judged (docs/fss.md, "Calibrated").
    relative = all('reference' in it for it in chosen)
    try:
        model = train_model(chosen, bins=args.bins, c=args.c, seed=args.seed,
                            use=args.use, relative=relative)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    model.spec['trained_on'] = {'dataset': str(args.dataset), 'windows': n_train,
                                'seed': args.seed, 'relative': relative}
    save_model(model, args.output)
    print(f'model trained on {n_train} windows written to {args.output}')
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from rwa_monitor.telemetry.fss_model import load_model
    try:
        model = load_model(args.model)
    except (OSError, ValueError) as err:
        raise ConfigError(str(err)) from None
    items = _items(args.dataset)
    relative = bool(model.spec.get('relative')) and all('reference' in it for it in items)
    if model.spec.get('relative') and not relative:
        print('note: the data set has no reference windows (legacy); the relative model '
              'is given absolute features', file=sys.stderr)
    matrix = detection_matrix(model, items, relative=relative)
    names = list(next(iter(matrix.values())))
    print('status      ' + ''.join(f'{n:>9}' for n in names))
    for status, row in matrix.items():
        print(f'{status:<12}' + ''.join(f'{100 * row[n]:8.1f}%' for n in names))
    if args.output:
        write_text_atomic(args.output, json.dumps({'detection': matrix}, indent=1))
    return 0
