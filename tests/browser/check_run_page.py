#!/usr/bin/python3
"""Runs a pipeline, then opens its run page (WORKDIR/report.html) in headless Chromium, as a person
would, and checks it (issue 32): every image name of the scene and the verdict are in the page's
text, every camera row holds its frame verdict (issue 46); a click on a camera in the top view and
one in the orbit view each open that camera's panel with its image decoded; a drag turns the orbit
view; the console has no error or warning and no script threw. Drives Debian's chromium over the DevTools protocol on a pipe (--remote-debugging-pipe:
JSON messages separated by NUL on file descriptors 3 and 4), so it needs nothing beyond the
standard library. Exit 0: passed; 1: failed; 77: skipped (scene or chromium absent, and
RAYTIME_REQUIRE_BROWSER unset).

  check_run_page.py --raytime BIN --pipeline configs/demo.yaml --images-dir DIR [--set K=V ...]
                    [--workdir DIR] [--screenshot PNG]
  check_run_page.py --page WORKDIR/report.html --images-dir DIR     (a page already written)
"""

import argparse
import base64
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time

SKIP = 77


class Browser:
    """One headless Chromium with one page, driven over --remote-debugging-pipe."""

    def __init__(self, binary, profile_dir):
        to_chrome_read, self._to_chrome = os.pipe()
        self._from_chrome, from_chrome_write = os.pipe()

        # Chromium reads commands on fd 3 and writes replies and events on fd 4: a shell puts the
        # pipes there and execs it.
        self._process = subprocess.Popen(
            ['/bin/sh', '-c', 'exec "$0" "$@" 3<&%d 4>&%d' % (to_chrome_read, from_chrome_write),
             binary, '--headless', '--no-sandbox', '--disable-gpu', '--remote-debugging-pipe',
             '--user-data-dir=' + profile_dir, '--window-size=1400,1000', '--no-first-run',
             'about:blank'],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(to_chrome_read, from_chrome_write))
        os.close(to_chrome_read)
        os.close(from_chrome_write)
        self._buffer = b''
        self._next_id = 0
        self.events = []
        self.session = None

    def _read_message(self, deadline):
        while b'\0' not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError('no message from chromium in time')
            ready, _, _ = select.select([self._from_chrome], [], [], left)
            if ready:
                chunk = os.read(self._from_chrome, 1 << 20)
                if not chunk:
                    raise RuntimeError('chromium closed its DevTools pipe')
                self._buffer += chunk
        message, self._buffer = self._buffer.split(b'\0', 1)
        return json.loads(message)

    def call(self, method, params=None, timeout=30, session=True):
        self._next_id += 1
        message = {'id': self._next_id, 'method': method, 'params': params or {}}
        if session and self.session:
            message['sessionId'] = self.session
        os.write(self._to_chrome, json.dumps(message).encode() + b'\0')
        deadline = time.monotonic() + timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get('id') == self._next_id:
                if 'error' in reply:
                    raise RuntimeError('%s: %s' % (method, reply['error']))
                return reply.get('result', {})
            self.events.append(reply)

    def wait_for_event(self, method, timeout=30):
        deadline = time.monotonic() + timeout
        for event in self.events:
            if event.get('method') == method:
                return event
        while True:
            event = self._read_message(deadline)
            self.events.append(event)
            if event.get('method') == method:
                return event

    def open(self, url):
        target = self.call('Target.createTarget', {'url': 'about:blank'}, session=False)
        attached = self.call('Target.attachToTarget',
                             {'targetId': target['targetId'], 'flatten': True}, session=False)
        self.session = attached['sessionId']
        for domain in ('Page', 'Runtime', 'Log'):
            self.call(domain + '.enable')
        self.call('Page.navigate', {'url': url})
        self.wait_for_event('Page.loadEventFired', timeout=60)

    def evaluate(self, expression):
        result = self.call('Runtime.evaluate', {'expression': expression, 'returnByValue': True,
                                                'awaitPromise': True})
        if 'exceptionDetails' in result:
            raise RuntimeError('page script failed: %s' % result['exceptionDetails'])
        return result['result'].get('value')

    def mouse(self, kind, x, y, buttons=0):
        params = {'type': kind, 'x': x, 'y': y, 'button': 'left' if kind != 'mouseMoved' or buttons
                  else 'none', 'buttons': buttons}
        if kind in ('mousePressed', 'mouseReleased'):
            params['clickCount'] = 1
        self.call('Input.dispatchMouseEvent', params)

    def click(self, x, y):
        self.mouse('mouseMoved', x, y)
        self.mouse('mousePressed', x, y, buttons=1)
        self.mouse('mouseReleased', x, y)

    def problems(self):
        """Console errors and warnings, uncaught exceptions, failed loads, as text."""
        found = []
        for event in self.events:
            method, params = event.get('method'), event.get('params', {})
            if method == 'Runtime.consoleAPICalled' and params.get('type') in ('error', 'warning',
                                                                                'assert'):
                found.append('console.%s: %s' % (params['type'], [a.get('value') for a in
                                                                   params.get('args', [])]))
            elif method == 'Runtime.exceptionThrown':
                details = params['exceptionDetails']
                found.append('exception: %s' % details.get('exception', {}).get(
                    'description', details.get('text')))
            elif method == 'Log.entryAdded' and params['entry'].get('level') in ('error',
                                                                                 'warning'):
                found.append('log: %s' % params['entry'].get('text'))
        return found

    def close(self):
        try:
            self.call('Browser.close', session=False, timeout=5)
        except Exception:  # already gone: nothing to close
            pass
        try:
            self._process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._process.kill()


def fail(message):
    print('FAIL: ' + message)
    return 1


def click_and_check_panel(browser, name, x, y, where):
    browser.click(x, y)
    state = browser.evaluate(
        '(() => { const panel = document.getElementById(%s); if (!panel) return null;'
        ' const image = panel.querySelector("img");'
        ' return {hash: decodeURIComponent(location.hash),'
        ' display: getComputedStyle(panel).display, text: panel.innerText,'
        ' image: image ? image.complete && image.naturalWidth : 0}; })()'
        % json.dumps('cam-' + name))
    if state is None:
        return 'no panel for %s' % name
    if state['hash'] != '#cam-' + name:
        return 'a click on %s in the %s left the page at %r' % (name, where, state['hash'])
    if state['display'] != 'block':
        return "%s's panel is not shown after a click in the %s" % (name, where)
    for needed in (name, 'rotation correction', 'residual median'):
        if needed not in state['text']:
            return "%s's panel lacks %r" % (name, needed)
    if not state['image']:
        return "%s's panel shows no decoded image" % name
    print('clicked %s in the %s: its panel opened with its image (%d px wide)'
          % (name, where, state['image']))
    return None


def check(browser, page, names, screenshot):
    browser.open('file://' + os.path.abspath(page))
    text = browser.evaluate('document.body.innerText')
    missing = [n for n in names if n not in text]
    if missing:
        return fail('%d image name(s) not on the page, e.g. %s' % (len(missing), missing[:5]))
    if 'Status: ok' not in text or 'decision' not in text:
        return fail('no verdict ("Status: ok" and the refine decision) on the page')
    print('page text holds the verdict and all %d image names' % len(names))
    # Every camera's row says its frame verdict (issue 46), and the verdict names the counts.
    verdicts = browser.evaluate(
        '(() => { const rows = document.querySelectorAll("#camera-table tr[id^=row-]");'
        ' return Array.from(rows).map(r => { const v = r.querySelector("span.verdict");'
        ' return v ? v.textContent : null; }); })()')
    if not verdicts or len(verdicts) != len(names) or any(
            v is None or v.split(' ')[0] not in ('held', 'held_by_prior', 'doubted')
            for v in verdicts):
        return fail('the camera table does not give every frame a verdict: %s' % verdicts[:5])
    if 'held by their matches' not in text:
        return fail('the verdict section does not count the frame verdicts')
    print('every camera row holds its frame verdict (%d held)' %
          sum(1 for v in verdicts if v == 'held'))

    # A camera in the top view: a real mouse click at its circle. In a dense capture circles
    # overlap: the click opens the one drawn on top there.
    target = names[len(names) // 2]
    box = browser.evaluate(
        '(() => { const c = document.querySelector(%s); if (!c) return null;'
        ' c.scrollIntoView({block: "center"}); const b = c.getBoundingClientRect();'
        ' const x = b.left + b.width / 2, y = b.top + b.height / 2;'
        ' const top = document.elementFromPoint(x, y);'
        ' return [x, y, top && top.dataset ? top.dataset.name : null]; })()'
        % json.dumps('#cameras-top circle.camera[data-name="%s"]' % target))
    if box is None:
        return fail('no camera %s in the top view' % target)
    if box[2] not in names:
        return fail('no camera under the centre of %s in the top view' % target)
    problem = click_and_check_panel(browser, box[2], box[0], box[1], 'top view')
    if problem:
        return fail(problem)

    # The orbit view: a drag turns it (no click), then a click on another camera opens it.
    browser.evaluate('document.getElementById("orbit").scrollIntoView({block: "center"})')
    corner = browser.evaluate(
        '(() => { const b = document.getElementById("orbit").getBoundingClientRect();'
        ' return [b.left + 20, b.top + 20]; })()')
    yaw = browser.evaluate('window.raytimeOrbit.view.yaw')
    browser.mouse('mouseMoved', corner[0], corner[1])
    browser.mouse('mousePressed', corner[0], corner[1], buttons=1)
    browser.mouse('mouseMoved', corner[0] + 60, corner[1] + 10, buttons=1)
    browser.mouse('mouseReleased', corner[0] + 60, corner[1] + 10)
    if browser.evaluate('window.raytimeOrbit.view.yaw') == yaw:
        return fail('a drag did not turn the orbit view')
    other = names[0] if names[0] != target else names[-1]
    position = browser.evaluate('window.raytimeOrbit.screenPosition(%s)' % json.dumps(other))
    if position is None:
        return fail('camera %s is not in the orbit view' % other)
    problem = click_and_check_panel(browser, other, position[0], position[1], 'orbit view')
    if problem:
        return fail(problem)

    if screenshot:
        shot = browser.call('Page.captureScreenshot', {'format': 'png'})
        with open(screenshot, 'wb') as f:
            f.write(base64.b64decode(shot['data']))
    problems = browser.problems()
    if problems:
        return fail('the console has %d problem(s): %s' % (len(problems), problems[:5]))
    print('console clean')
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--raytime', help='the raytime binary')
    parser.add_argument('--pipeline', help='pipeline YAML to run')
    parser.add_argument('--page', help='check this page instead of running a pipeline')
    parser.add_argument('--images-dir', required=True,
                        help="the scene's image folder: every *.jpg / *.png name must be on the page")
    parser.add_argument('--set', action='append', default=[], help='STAGE.KEY=VALUE for raytime run')
    parser.add_argument('--workdir', help='work directory (default: a temporary one)')
    parser.add_argument('--screenshot', help='write a PNG of the page after the clicks here')
    args = parser.parse_args()
    required = os.environ.get('RAYTIME_REQUIRE_BROWSER') == '1'

    if not os.path.isdir(args.images_dir):
        print('SKIP: no scene at %s' % args.images_dir)
        return SKIP
    chromium = shutil.which('chromium') or shutil.which('chromium-browser')
    if chromium is None:
        print('%s: chromium is not installed (scripts/install_deps.sh --test installs it)'
              % ('FAIL' if required else 'SKIP'))
        return 1 if required else SKIP
    names = sorted(n for n in os.listdir(args.images_dir)
                   if n.lower().endswith(('.jpg', '.jpeg', '.png')))

    if not args.page and not (args.raytime and args.pipeline):
        parser.error('give --page, or --raytime and --pipeline')
    with tempfile.TemporaryDirectory(prefix='raytime_page_') as scratch:
        if args.page:
            browser = Browser(chromium, os.path.join(scratch, 'profile'))
            try:
                return check(browser, args.page, names, args.screenshot)
            finally:
                browser.close()
        workdir = args.workdir or os.path.join(scratch, 'run')
        command = [args.raytime, 'run', args.pipeline, '--workdir', workdir]
        for assignment in args.set:
            command += ['--set', assignment]
        run = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if run.returncode != 0:
            print(run.stdout[-4000:])
            return fail('raytime run exited with %d' % run.returncode)
        browser = Browser(chromium, os.path.join(scratch, 'profile'))
        try:
            return check(browser, os.path.join(workdir, 'report.html'), names, args.screenshot)
        finally:
            browser.close()


if __name__ == '__main__':
    sys.exit(main())
