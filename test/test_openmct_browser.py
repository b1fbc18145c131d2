"""Every page the project serves or writes, in a real browser (Debian's chromium).

On a small simulated fleet (``simulate fleet`` then ``fleet``): the operator's view shows
every spacecraft with no console error and no request leaving the machine, the wheels
with events stand out; the fleet's report.html loads with no error nor outside request,
names every spacecraft and holds plots of a readable size. Live: during a replay with an
injected fault, a wheel's plot receives points and its anomaly appears. Screenshots go to
``$RWA_MONITOR_SCREENSHOTS`` (``make screenshots``: docs/images) or the test's folder.
"""

import json
import os
import pathlib
import subprocess
import sys
import time

from browser import browser, start_server, stop, VIEWPORT, Watch
import pytest
from ros_harness import DomainLease

from rwa_monitor.openmct.history import level_of

pytestmark = pytest.mark.timeout(600)
FLEET_SEED = 4207
LIVE_SEED = 4211


def _shots(tmp_path):
    folder = os.environ.get('RWA_MONITOR_SCREENSHOTS')
    path = pathlib.Path(folder) if folder else tmp_path
    path.mkdir(parents=True, exist_ok=True)
    return path


def _cli(*args, env=None):
    done = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', *args], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode in (0, 1, 3), done.stdout + done.stderr
    return done


@pytest.fixture(scope='module')
def fleet(tmp_path_factory):
    """Return the output folder of a 3-spacecraft, 3-day simulated fleet with 2 faults."""
    from browser import chromium_or_skip
    chromium_or_skip()
    base = tmp_path_factory.mktemp('fleet')
    _cli('simulate', 'fleet', '-o', str(base / 'archive'), '--spacecraft', '3', '--days', '3',
         '--faults', '2', '--seed', str(FLEET_SEED))
    _cli('fleet', str(base / 'archive'), '-o', str(base / 'out'), '--workers', '1')
    return base / 'out'


def _anomalous_wheels(out):
    """Return the (spacecraft, wheel) pairs whose events leave an anomaly at the end."""
    latest = {}
    for e in json.loads((out / 'events.json').read_text())['events']:
        latest[(e['spacecraft'], e['component'], e['index'])] = e['kind']
    return {(craft, wheel) for (craft, wheel, _), kind in latest.items() if level_of(kind)}


def test_the_operators_view_shows_every_spacecraft_of_the_fleet(fleet, tmp_path):
    crafts = sorted(json.loads((fleet / 'summary.json').read_text())['spacecraft'])
    anomalous = _anomalous_wheels(fleet)
    assert len(crafts) == 3 and anomalous, 'the fleet must hold a fault the view can show'
    server, url = start_server(['--fleet', str(fleet)])
    try:
        with browser() as chrome:
            page = chrome.new_page(viewport=VIEWPORT)
            watch = Watch(page, [url.rstrip('/')])
            page.goto(url)
            for craft in crafts:
                page.get_by_text(f'{craft}: anomaly states').first.wait_for(timeout=60_000)
            # every anomalous wheel's state row carries an Open MCT limit class
            page.wait_for_function(
                'n => document.querySelectorAll(".is-limit--yellow, .is-limit--red").length'
                ' >= n', arg=len(anomalous), timeout=60_000)
            flagged = set()
            for craft in crafts:
                frame = page.locator('.c-so-view', has=page.get_by_text(
                    f'{craft}: anomaly states', exact=True))
                rows = frame.locator('tr:has(.is-limit--yellow), tr:has(.is-limit--red)')
                flagged |= {(craft, rows.nth(i).inner_text().split()[0])
                            for i in range(rows.count())}
            page.screenshot(path=str(_shots(tmp_path) / 'openmct-fleet.png'))
            # one spacecraft's display: its plots and its events table
            craft = sorted(anomalous)[0][0]
            page.goto(f'{url}#/browse/rwa:root/rwa:{craft}/rwa:{craft}.display')
            page.get_by_text(f'{craft}: events').first.wait_for(timeout=60_000)
            page.locator('canvas').first.wait_for(timeout=60_000)
            time.sleep(2)
            page.screenshot(path=str(_shots(tmp_path) / 'openmct-spacecraft.png'))
    finally:
        log = stop(server)
    assert not watch.errors, watch.errors
    assert not watch.outside, watch.outside
    assert not watch.failed, watch.failed
    assert flagged == anomalous, (flagged, anomalous, log)


def test_the_fleet_report_loads_with_no_error_and_legible_plots(fleet, tmp_path):
    crafts = sorted(json.loads((fleet / 'summary.json').read_text())['spacecraft'])
    report = fleet / 'report.html'
    with browser() as chrome:
        page = chrome.new_page(viewport={'width': 1400, 'height': 1000})
        watch = Watch(page, [report.as_uri()])
        page.goto(report.as_uri())
        page.wait_for_load_state('load')
        title = page.title()
        tables = page.locator('table')
        table_text = ' '.join(tables.nth(i).inner_text() for i in range(tables.count()))
        sizes = page.eval_on_selector_all(
            'img', 'els => els.map(e => [e.naturalWidth, e.naturalHeight, e.clientWidth])')
        page.screenshot(path=str(_shots(tmp_path) / 'fleet-report.png'), full_page=False)
        plot = page.locator('img').first
        plot.scroll_into_view_if_needed()
        plot.screenshot(path=str(_shots(tmp_path) / 'fleet-report-plot.png'))
    assert not watch.errors, watch.errors
    assert not watch.outside, watch.outside
    assert 'fleet' in title.lower() or 'report' in title.lower(), title
    assert all(craft in table_text for craft in crafts), table_text[:500]
    assert sizes, 'no plot image in the report'
    # a plot a person can read on a laptop: at least 600 x 200 pixels, not shrunk on the
    # page (shown at 90 % of its width or more)
    assert all(w >= 600 and h >= 200 and shown >= 0.9 * w for w, h, shown in sizes), sizes


def _live_file(tmp_path):
    """Write a 4-wheel, 25-minute file with a dry step on rw2 at 600 s; return its path."""
    path = tmp_path / 'live.csv'
    _cli('simulate', 'friction', '--wheels', '4', '--seconds', '1500', '--rate', '10',
         '--anomaly', 'rw2:dry:600:+6e-4', '--seed', str(LIVE_SEED), '-o', str(path))
    return path


def _plot_pixels(page, title):
    """Return the PNG bytes of the plot frame whose title is ``title``."""
    frame = page.locator('.c-so-view', has=page.get_by_text(title, exact=True)).first
    return frame.screenshot()


def test_a_live_replay_reaches_the_plot_and_its_fault_raises_the_anomaly(tmp_path):
    from browser import chromium_or_skip
    chromium_or_skip()
    path = _live_file(tmp_path)
    lease = DomainLease()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    server, url = start_server(['--live'], env=env)
    procs = []
    try:
        procs.append(subprocess.Popen([sys.executable, '-m', 'rwa_monitor.nodes.llr_detector',
                                       '--ros-args', '-p', 'stale_timeout:=60.0'], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
        with browser() as chrome:
            page = chrome.new_page(viewport=VIEWPORT)
            watch = Watch(page, [url.rstrip('/'), url.replace('http', 'ws').rstrip('/')])
            frames = []
            page.on('websocket', lambda ws: ws.on(
                'framereceived', lambda f: frames.append(f) if 'live.rw2.friction' in f
                else None))
            page.goto(url)      # the fleet overview, empty until the replay starts
            page.get_by_text('Fleet: anomaly states').first.wait_for(timeout=60_000)
            procs.append(subprocess.Popen(
                [sys.executable, '-m', 'rwa_monitor.nodes.replay', '--ros-args',
                 '-p', f'file:={path}', '-p', 'rate:=20.0', '-p', 'min_subscribers:=2'],
                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
            # the live spacecraft joins the open overview as its data arrive
            page.get_by_text('live: anomaly states').first.wait_for(timeout=90_000)
            page.goto(f'{url}#/browse/rwa:root/rwa:live/rwa:live.display')
            title = 'live rw2 friction and residual'
            page.get_by_text(title, exact=True).wait_for(timeout=90_000)
            time.sleep(2)
            before = _plot_pixels(page, title)
            time.sleep(4)
            after = _plot_pixels(page, title)
            received = len(frames)
            # the fault at 600 s is declared by the detector, latched, shown as a limit
            anomaly = page.locator('tr:has-text("rw2 anomaly state") .is-limit--yellow')
            anomaly.wait_for(timeout=120_000)
            page.get_by_text('dry', exact=True).first.wait_for(timeout=30_000)
            state = page.locator('tr:has-text("rw2 anomaly state") td').last.inner_text()
            others = [page.locator(f'tr:has-text("{w} anomaly state") td').last.inner_text()
                      for w in ('rw1', 'rw3', 'rw4')]
            time.sleep(1)
            page.screenshot(path=str(_shots(tmp_path) / 'openmct-live.png'))
    finally:
        for proc in procs:
            stop(proc)
        log = stop(server)
        lease.release()
    assert received > 0, 'no live friction of rw2 reached the page'
    assert before != after, 'the rw2 plot did not change while the replay ran'
    assert state == 'anomaly (warning)' and others == ['nominal'] * 3, (state, others)
    assert not watch.errors, (watch.errors, log[-3000:])
    assert not watch.outside, (watch.outside, log)
