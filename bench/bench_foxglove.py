"""``python -m bench foxglove``: what the bridge's WebSocket front costs per message.

One client (a ``websockets`` client in its own process) subscribes to one JSON channel of
a foxglove-sdk server and counts the messages it receives while this process logs wheel
samples (the bridge's ``/rwa_monitor/wheels`` payload, 4 wheels) at a fixed rate: once
straight to the SDK's port (the client offers ``foxglove.sdk.v1``), once through
:class:`~rwa_monitor.nodes.foxglove_front.WebSocketFront` (the client offers
``foxglove.websocket.v1``; the SDK's server behind TLS, as the bridge runs
it), alternated ``repeats`` times in the same run. Reported: the
messages delivered and this process's CPU time per message (producer, SDK and relay
threads together; the producer's share is the same in both arms). Results:
bench/results/foxglove.json and the ``foxglove`` section of docs/results.md.
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import time
from typing import Any

import numpy as np

from bench import report

CLIENT = '''
import json, sys, time
from websockets.sync.client import connect
url, protocol, expected = sys.argv[1], sys.argv[2], int(sys.argv[3])
with connect(url, subprotocols=[protocol], max_size=None, compression=None) as ws:
    while True:
        frame = ws.recv(timeout=30)
        if isinstance(frame, str) and json.loads(frame).get('op') == 'advertise':
            channel = json.loads(frame)['channels'][0]['id']
            break
    subscription = {'id': 1, 'channelId': channel}
    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [subscription]}))
    print('ready', flush=True)
    received, first, last = 0, None, None
    while received < expected:
        try:
            frame = ws.recv(timeout=3.0)
        except TimeoutError:
            break
        if isinstance(frame, bytes) and frame[0] == 1:
            received += 1
            last = time.perf_counter()
            first = first or last
    print(json.dumps({'received': received, 'seconds': (last or 0) - (first or 0)}))
'''


def _sample(k: int) -> bytes:
    wheels = {f'rw{i}': {'speed_rad_s': 100.0 + k * 1e-3, 'friction_nm': -2.1e-4}
              for i in range(1, 5)}
    return json.dumps({'time_s': k * 0.1, 'wheels': wheels}).encode()


def _one_run(through_front: bool, rate: float, count: int) -> dict[str, Any]:
    import foxglove

    from rwa_monitor.nodes.foxglove_front import loopback_certificate, trusting, WebSocketFront
    context = foxglove.Context()
    channel = foxglove.Channel('/rwa_monitor/wheels', schema={'type': 'object'},
                               context=context)
    # The front arm as the bridge runs it: the SDK's server behind TLS (issue 36).
    certificate, key = loopback_certificate() if through_front else (None, None)
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context,
                                   tls_cert=certificate, tls_key=key)
    front = WebSocketFront('127.0.0.1', 0, server.port, [], print,
                           upstream_tls=trusting(certificate)) if through_front else None
    port, protocol = ((front.port, 'foxglove.websocket.v1') if front else
                      (server.port, 'foxglove.sdk.v1'))
    client = subprocess.Popen([sys.executable, '-c', CLIENT, f'ws://127.0.0.1:{port}',
                               protocol, str(count)], stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout.readline().strip() == 'ready'
        deadline = time.monotonic() + 30.0
        while not channel.has_sinks() and time.monotonic() < deadline:
            time.sleep(0.01)
        payloads = [_sample(k) for k in range(count)]
        cpu, start = time.process_time(), time.perf_counter()
        for k, payload in enumerate(payloads):
            ahead = start + k / rate - time.perf_counter()
            if ahead > 0.002:
                time.sleep(ahead)
            channel.log(payload, log_time=k)
        result = json.loads(client.stdout.readline())
        cpu = time.process_time() - cpu
        client.wait(timeout=30)
    finally:
        if client.poll() is None:
            client.kill()
        if front is not None:
            front.stop()
        server.stop()
    return {'delivered': result['received'] / count, 'cpu_us_per_message': 1e6 * cpu / count,
            'received_per_s': result['received'] / max(result['seconds'], 1e-9)}


def run(out_dir: pathlib.Path, quick: bool = False) -> dict[str, Any]:
    """Run the benchmark; write JSON and the docs section; return the results."""
    rates, seconds, repeats = ((3000.0,), 2.0, 1) if quick else ((500.0, 3000.0), 10.0, 3)
    rows = []
    for rate in rates:
        runs = {'direct': [], 'front': []}
        for _ in range(repeats):
            for arm in ('direct', 'front'):
                runs[arm].append(_one_run(arm == 'front', rate, int(rate * seconds)))
        row = {'rate_per_s': rate, 'messages': int(rate * seconds)}
        for arm, results in runs.items():
            row[arm] = {key: float(np.median([r[key] for r in results]))
                        for key in results[0]}
        row['cpu_ratio'] = row['front']['cpu_us_per_message'] / \
            row['direct']['cpu_us_per_message']
        rows.append(row)
    load = os.getloadavg()
    results = {'rows': rows, 'repeats': repeats, 'load_average': load, 'quick': quick}
    report.write_json(out_dir, 'foxglove', results)
    lines = [f'One client, one JSON channel, wheel samples of 4 wheels; median of {repeats} '
             f'alternated runs per arm; load average {load[0]:.1f} / {load[1]:.1f} / '
             f'{load[2]:.1f} (1/5/15 min) at the end. `python -m bench foxglove`; method: '
             'bench/bench_foxglove.py docstring.', '',
             '| rate (msg/s) | arm | delivered | CPU per message (us) | front / direct CPU |',
             '|---|---|---|---|---|']
    for row in rows:
        for arm in ('direct', 'front'):
            ratio = f'{row["cpu_ratio"]:.2f}' if arm == 'front' else ''
            lines.append(f'| {row["rate_per_s"]:.0f} | {arm} | '
                         f'{100 * row[arm]["delivered"]:.1f} % | '
                         f'{row[arm]["cpu_us_per_message"]:.0f} | {ratio} |')
    if not quick:
        report.update_section('foxglove', '\n'.join(lines))
    print('\n'.join(lines))
    return results
