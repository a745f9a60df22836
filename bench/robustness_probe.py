#!/usr/bin/python3
"""Issue 47 probe: 46 adversarial / new-user cases (bad pipeline files and overrides, odd datasets,
work directories in the way, priors, edge options, other commands, signals) run against one raytime
binary. Usage: bench/robustness_probe.py BIN OUTDIR. Writes OUTDIR/results.json (exit status,
summary status and cause, last output lines); the verdicts are a reader's (docs/robustness_probe.md).
Case 26 writes ~/w26 (the home folder): remove it afterwards."""
import json, os, shutil, signal, subprocess, sys, time
BIN, OUT = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
SRC = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLE = SRC + '/data/sample/fountain-P11'
DEMO = SRC + '/configs/demo.yaml'
shutil.rmtree(OUT, ignore_errors=True); os.makedirs(OUT)
results = {}

def sh(cmd, timeout=300, env=None):
    e = dict(os.environ); e.update(env or {})
    try:
        p = subprocess.run(['bash', '-c', cmd], cwd=SRC, capture_output=True, text=True, timeout=timeout, env=e)
        return p.returncode, (p.stdout + p.stderr)
    except subprocess.TimeoutExpired as ex:
        return 'timeout', str(ex)

def scene(name):
    d = os.path.join(OUT, name); shutil.copytree(SAMPLE, d); return d

def summary(wd):
    try: return json.load(open(os.path.join(wd, 'summary.json')))
    except Exception as ex: return {'status': 'absent' if not os.path.exists(os.path.join(wd, 'summary.json')) else 'unreadable'}

def case(name, cmd, wd=None, env=None, timeout=300):
    rc, out = sh(cmd, timeout, env)
    s = summary(wd) if wd else {}
    lines = [l for l in out.strip().split('\n') if l.strip()]
    results[name] = {'rc': rc, 'status': s.get('status'), 'cause': s.get('cause'),
                     'error': (s.get('error') or '')[:300],
                     'tail': [l[:300] for l in lines[-3:]]}
    print(name, rc, s.get('status'), s.get('cause'), '|', (lines[-1][:200] if lines else ''), flush=True)
    json.dump(results, open(os.path.join(OUT, 'results.json'), 'w'), indent=1)

def demo(wd, extra=''):
    return f'{BIN} run {DEMO} --workdir {wd} {extra}'

# A finished base run, copied (cp -a) where a case needs earlier results.
base = os.path.join(OUT, 'base'); sh(demo(base))
def from_base(name):
    wd = os.path.join(OUT, name); sh(f'cp -a {base} {wd}'); return wd

W = lambda n: os.path.join(OUT, n)
# --- command line and pipeline files
os.makedirs(W('adir'))
case('01 pipeline path is a folder', f'{BIN} run {W("adir")} --workdir {W("w01")}', W('w01'))
open(W('empty.yaml'), 'w').close()
case('02 empty pipeline file', f'{BIN} run {W("empty.yaml")} --workdir {W("w02")}', W('w02'))
open(W('nostages.yaml'), 'w').write('name: x\ndataset: {format: strecha, root: %s}\nstages: []\n' % SAMPLE)
case('03 pipeline with no stages', f'{BIN} run {W("nostages.yaml")} --workdir {W("w03")}', W('w03'))
open(W('tabs.yaml'), 'w').write('name: x\ndataset:\n\tformat: strecha\n')
case('04 YAML indented with a tab', f'{BIN} run {W("tabs.yaml")} --workdir {W("w04")}', W('w04'))
case('05 --set without =', demo(W('w05'), '--set refine.preset'), W('w05'))
case('06 --set of an unknown stage', demo(W('w06'), '--set nosuch.key=1'), W('w06'))
case('07 unknown refine preset', demo(W('w07'), '--set refine.preset=doesnotexist'), W('w07'))
open(W('dup.yaml'), 'w').write(open(DEMO).read().replace('  - refine: {preset: auto}', '  - refine: {preset: auto}\n  - refine: {preset: basin}'))
case('08 a stage twice without @name', f'{BIN} run {W("dup.yaml")} --workdir {W("w08")}', W('w08'))
# --- datasets
open(W('afile'), 'w').write('x')
case('09 dataset root is a file', demo(W('w09'), f'--set dataset.root={W("afile")}'), W('w09'))
os.makedirs(W('emptyds'))
case('10 dataset root is empty', demo(W('w10'), f'--set dataset.root={W("emptyds")}'), W('w10'))
d = scene('ds11'); open(os.path.join(d, 'images', '0004.jpg'), 'w').close()
case('11 a zero-byte image', demo(W('w11'), f'--set dataset.root={d}'), W('w11'))
d = scene('ds12'); p = os.path.join(d, 'images', '0004.jpg'); b = open(p, 'rb').read(); open(p, 'wb').write(b[:len(b)//2])
case('12 a truncated JPEG', demo(W('w12'), f'--set dataset.root={d}'), W('w12'))
d = scene('ds13'); p = os.path.join(d, 'gt_dense_cameras', '0004.jpg.camera'); t = open(p).read().split('\n'); t[0] = 'nan nan nan'; open(p, 'w').write('\n'.join(t))
case('13 a camera file with NaN', demo(W('w13'), f'--set dataset.root={d}'), W('w13'))
d = scene('ds14'); [os.remove(os.path.join(d, 'images', f)) for f in os.listdir(os.path.join(d, 'images')) if f != '0000.jpg']; [os.remove(os.path.join(d, 'gt_dense_cameras', f)) for f in os.listdir(os.path.join(d, 'gt_dense_cameras')) if not f.startswith('0000')]
case('14 a dataset of one image', demo(W('w14'), f'--set dataset.root={d}'), W('w14'))
d = scene('ds15'); [os.remove(os.path.join(d, 'images', f)) for f in os.listdir(os.path.join(d, 'images')) if f not in ('0000.jpg', '0001.jpg')]; [os.remove(os.path.join(d, 'gt_dense_cameras', f)) for f in os.listdir(os.path.join(d, 'gt_dense_cameras')) if f[:4] not in ('0000', '0001')]
case('15 a dataset of two images', demo(W('w15'), f'--set dataset.root={d}'), W('w15'))
d = scene('ds16'); shutil.copy(os.path.join(d, 'images', '0004.jpg'), os.path.join(d, 'images', '0005.jpg'))
case('16 one image duplicated under another name', demo(W('w16'), f'--set dataset.root={d}'), W('w16'))
d = scene('ds17'); os.remove(os.path.join(d, 'images', '0006.jpg')); os.symlink('0002.jpg', os.path.join(d, 'images', '0006.jpg'))
case('17 an image symlinked to another', demo(W('w17'), f'--set dataset.root={d}'), W('w17'))
d = scene('ds18'); os.remove(os.path.join(d, 'images', '0006.jpg')); os.symlink('nowhere.jpg', os.path.join(d, 'images', '0006.jpg'))
case('18 a dangling image symlink', demo(W('w18'), f'--set dataset.root={d}'), W('w18'))
d = scene('ds19'); os.rename(os.path.join(d, 'images', '0003.jpg'), os.path.join(d, 'images', '00\n03.jpg')); os.rename(os.path.join(d, 'gt_dense_cameras', '0003.jpg.camera'), os.path.join(d, 'gt_dense_cameras', '00\n03.jpg.camera'))
case('19 an image name with a newline', demo(W('w19'), f'--set dataset.root={d} --set export.formats=[colmap_text]'), W('w19'))
d = scene('ds20'); shutil.copy(SRC + '/docs/report_demo.png', os.path.join(d, 'images', '0007.jpg'))
case('20 a PNG (another size) named .jpg', demo(W('w20'), f'--set dataset.root={d}'), W('w20'))
# --- work directories
open(W('w21'), 'w').write('x')
case('21 the work directory is a file', demo(W('w21')), W('w21'))
case('22 a work directory with spaces and unicode', demo("'" + W('w 22 é') + "'"), W('w 22 é'))
case('23 a work directory name too long', demo(W('w23_' + 'x' * 300)), None)
os.makedirs(W('w24')); os.makedirs(W('w24/summary.json'))
case('24 summary.json is a folder', demo(W('w24')), None)
os.makedirs(W('w25')); open(W('w25/.raytime'), 'w').write('x')
case('25 WORKDIR/.raytime is a file', demo(W('w25')), W('w25'))
case('26 HOME unset, workdir ~/x', demo("'~/w26'"), None, env={'HOME': ''})
case('27 ~nosuchuser/w', demo("'~nosuchuser/w27'"), None)
case('28 --cache-dir is a file', demo(W('w28'), f'--cache-dir {W("afile")}'), W('w28'))
# --- priors
case('29 prior file that does not exist', demo(W('w29'), f'--set prior.source=file --set prior.format=colmap --set prior.path={W("nope")}'), W('w29'))
open(W('empty_transforms.json'), 'w').write('{}')
case('30 an empty transforms.json prior', demo(W('w30'), f'--set prior.source=file --set prior.format=nerfstudio --set prior.path={W("empty_transforms.json")}'), W('w30'))
wd = from_base('w31'); tr = json.load(open(os.path.join(base, 'refined_transforms.json'))); tr['frames'][2]['transform_matrix'][0][0] = float('nan'); open(W('nan_transforms.json'), 'w').write(json.dumps(tr).replace('NaN', 'NaN'))
case('31 a prior pose with NaN', demo(wd, f'--set prior.source=file --set prior.format=nerfstudio --set prior.path={W("nan_transforms.json")}'), wd)
tr = json.load(open(os.path.join(base, 'refined_transforms.json'))); tr['frames'] = tr['frames'][:1]; open(W('one_transforms.json'), 'w').write(json.dumps(tr))
wd = from_base('w32')
case('32 a prior with one pose of eleven', demo(wd, f'--set prior.source=file --set prior.format=nerfstudio --set prior.path={W("one_transforms.json")}'), wd)
# --- options at their edges (not NaN/inf/huge: the table test has those)
wd = from_base('w33'); case('33 features.max_features=1', demo(wd, '--set features.max_features=1'), wd)
wd = from_base('w34'); case('34 matches.min_num_inliers=100000', demo(wd, '--set matches.min_num_inliers=100000'), wd)
wd = from_base('w35'); case('35 refine.max_iterations=1', demo(wd, '--set refine.max_iterations=1'), wd)
wd = from_base('w36'); case('36 refine.gnc_scales=[]', demo(wd, "--set 'refine.gnc_scales=[]'"), wd)
wd = from_base('w37'); case('37 export.formats=[]', demo(wd, "--set 'export.formats=[]'"), wd)
wd = from_base('w38'); case('38 export of a pose set nobody wrote', demo(wd, "--set 'export.poses=[nosuch]'"), wd)
wd = from_base('w39'); case('39 evaluate against a missing reference', demo(wd, '--set evaluate.reference=nosuch'), wd)
# --- other commands
case('40 a stage alone on a missing input', f'{BIN} refine --in {W("nope.h5")} --out {W("r.h5")}')
case('41 a stage alone without the artifacts it needs', f'{BIN} refine --in {base}/dataset.h5 --out {W("r41.h5")}')
case('42 report --run on a folder without a run', f'{BIN} report --run {W("adir")}')
case('43 resize-scene --width 0', f'{BIN} resize-scene --root {SAMPLE} --out {W("rs43")} --width 0')
# --- signals
def signal_case(name, sig, to_child):
    wd = W(name.split()[0] + 'w'); 
    p = subprocess.Popen(['bash', '-c', 'exec ' + demo(wd) + ' > %s/%s.log 2>&1' % (OUT, name.split()[0])], cwd=SRC)
    pid = None
    for _ in range(600):
        time.sleep(0.05)
        s = summary(wd)
        if s.get('status') == 'running' and s.get('stage') == 'matches': pid = s.get('pid'); break
    target = pid if to_child else p.pid
    if target: os.kill(target, sig)
    rc = p.wait(timeout=300)
    s = summary(wd)
    results[name] = {'rc': rc, 'status': s.get('status'), 'cause': s.get('cause'), 'error': (s.get('error') or '')[:300], 'tail': open('%s/%s.log' % (OUT, name.split()[0])).read().strip().split('\n')[-2:], 'report': os.path.exists(os.path.join(wd, 'report.html'))}
    print(name, rc, s.get('status'), s.get('cause'), flush=True)
    json.dump(results, open(os.path.join(OUT, 'results.json'), 'w'), indent=1)
signal_case('44 SIGKILL of the run process (an OOM kill)', signal.SIGKILL, True)
signal_case('45 SIGHUP to raytime (terminal closed)', signal.SIGHUP, False)
signal_case('46 SIGTERM to raytime', signal.SIGTERM, False)
print('done')
