#!/usr/bin/env python3
"""Mirrored and turned copies of the reference sets, with their truth moved
along: a probe of which answers hang on the exact pixels (README, "The
reference frames mirrored"). Needs Pillow.

  mirror_reference.py make REFERENCE_DIR COPIES_DIR
      writes COPIES_DIR/<copy>/<set>/ (frames, camera.yaml, truth.jsonl) for
      the copies left-right, top-bottom, half-turn and transposed
  mirror_reference.py run BINARY REFERENCE_DIR COPIES_DIR RESULTS_DIR
      runs `BINARY process SET --independent` on every set, as given and
      copied, into RESULTS_DIR/<copy>/<set>.jsonl
  mirror_reference.py score REFERENCE_DIR COPIES_DIR RESULTS_DIR
      prints per set and copy: detected, false, gross (position > 5 % of
      range or normal > 10 degrees, both normals of an unresolved answer
      given), centre and position medians (lower median), misses
"""
import json, math, os, re, subprocess, sys

SETS = ['paper10', 'range', 'tilt', 'occlusion', 'noise', 'hard', 'hard_b', 'hard_c', 'negative']
COPIES = ['hflip', 'vflip', 'rot180', 'transpose']


def read_camera(path):
    t = open(path).read()
    k = [float(v) for v in re.search(r'camera_matrix:.*?data: \[(.*?)\]', t, re.S).group(1).split(',')]
    d = [float(v) for v in re.search(r'distortion_coefficients:.*?data: \[(.*?)\]', t, re.S).group(1).split(',')]
    w = int(re.search(r'image_width: (\d+)', t).group(1))
    h = int(re.search(r'image_height: (\d+)', t).group(1))
    return w, h, k[0], k[4], k[2], k[5], d


def write_camera(path, w, h, fx, fy, cx, cy, d):
    open(path, 'w').write(
        f"image_width: {w}\nimage_height: {h}\ncamera_name: drogue_cam\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{fx}, 0.0, {cx}, 0.0, {fy}, {cy}, 0.0, 0.0, 1.0]\n"
        f"distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
        f"  data: [{', '.join(str(x) for x in d)}]\n"
        f"rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
        f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{fx}, 0.0, {cx}, 0.0, 0.0, {fy}, {cy}, 0.0, 0.0, 0.0, 1.0, 0.0]\n")


def make(ref, out):
    from PIL import Image
    for copy in COPIES:
        flip_u, flip_v, swap = copy in ('hflip', 'rot180'), copy in ('vflip', 'rot180'), copy == 'transpose'
        for s in SETS:
            d = f'{out}/{copy}/{s}'
            os.makedirs(d, exist_ok=True)
            w, h, fx, fy, cx, cy, (k1, k2, p1, p2, k3) = read_camera(f'{ref}/{s}/camera.yaml')
            # OpenCV pixel centres: a flip maps u to w - 1 - u; the
            # tangential terms change sign with their axis.
            if swap:
                write_camera(f'{d}/camera.yaml', h, w, fy, fx, cy, cx, [k1, k2, p2, p1, k3])
            else:
                write_camera(f'{d}/camera.yaml', w, h, fx, fy, w - 1 - cx if flip_u else cx,
                             h - 1 - cy if flip_v else cy,
                             [k1, k2, -p1 if flip_v else p1, -p2 if flip_u else p2, k3])
            with open(f'{d}/truth.jsonl', 'w') as truth_out:
                for line in open(f'{ref}/{s}/truth.jsonl'):
                    t = json.loads(line)
                    try:
                        im = Image.open(f'{ref}/{s}/{t["frame"]}')
                        im.load()
                    except Exception:
                        continue  # the hostile files of `badinput` are not copied
                    if swap:
                        im = im.transpose(Image.Transpose.TRANSPOSE)
                    else:
                        if flip_u:
                            im = im.transpose(Image.Transpose.FLIP_LEFT_RIGHT)
                        if flip_v:
                            im = im.transpose(Image.Transpose.FLIP_TOP_BOTTOM)
                    im.save(f'{d}/{t["frame"]}')

                    def move(p):
                        if p is None:
                            return None
                        x, y, z = p
                        return [y, x, z] if swap else [-x if flip_u else x, -y if flip_v else y, z]
                    for key in ('position_camera', 'normal_camera', 'alt_position_camera', 'alt_normal_camera'):
                        if key in t:
                            t[key] = move(t[key])
                    e = t.get('ellipse')
                    if e:
                        if swap:
                            e['cx'], e['cy'], e['theta'] = e['cy'], e['cx'], math.pi / 2 - e['theta']
                        else:
                            if flip_u:
                                e['cx'], e['theta'] = w - 1 - e['cx'], -e['theta']
                            if flip_v:
                                e['cy'], e['theta'] = h - 1 - e['cy'], -e['theta']
                    t.pop('scene', None)
                    truth_out.write(json.dumps(t) + '\n')


def set_dir(ref, copies, copy, s):
    return f'{ref}/{s}' if copy == 'given' else f'{copies}/{copy}/{s}'


def run(binary, ref, copies, results):
    for copy in ['given'] + COPIES:
        os.makedirs(f'{results}/{copy}', exist_ok=True)
        for s in SETS:
            d = set_dir(ref, copies, copy, s)
            subprocess.run([binary, 'process', d, '--camera', f'{d}/camera.yaml', '--independent',
                            '--out', f'{results}/{copy}/{s}.jsonl'],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)


def lower_median(v):
    v = sorted(v)
    return v[(len(v) - 1) // 2] if v else float('nan')


def score(ref, copies, results):
    def angle(n, m):
        return math.degrees(math.acos(max(-1.0, min(1.0, sum(a * b for a, b in zip(n, m))))))
    print('set | copy | detected | false | gross | centre px | position % | misses')
    for s in SETS:
        for copy in ['given'] + COPIES:
            truth = {json.loads(l)['frame']: json.loads(l) for l in open(f'{set_dir(ref, copies, copy, s)}/truth.jsonl')}
            got = {}
            for line in open(f'{results}/{copy}/{s}.jsonl'):
                x = json.loads(line)
                got[x['frame']] = x
            expected = detected = false = gross = 0
            centre, position, misses = [], [], []
            for frame, t in sorted(truth.items()):
                x = got.get(frame) or {}
                if t.get('expect') != 'detect':
                    false += bool(x.get('detected'))
                    continue
                expected += 1
                if not x.get('detected'):
                    misses.append(frame)
                    continue
                detected += 1
                e, te, tp = x['ellipse'], t['ellipse'], t['position_camera']
                rng = math.sqrt(sum(v * v for v in tp))
                centre.append(math.hypot(e['cx'] - te['cx'], e['cy'] - te['cy']))
                p = 100 * math.sqrt(sum((a - b) ** 2 for a, b in zip(x['position_camera'], tp))) / rng
                position.append(p)
                n = angle(x['normal_camera'], t['normal_camera'])
                if x.get('disambiguation') == 'unresolved' and x.get('normal_camera_alt'):
                    n = min(n, angle(x['normal_camera_alt'], t['normal_camera']))
                gross += p > 5 or n > 10
            print(f'{s} | {copy} | {detected}/{expected} | {false} | {gross} | '
                  f'{lower_median(centre):.3f} | {lower_median(position):.3f} | {" ".join(misses)}')


if __name__ == '__main__':
    a = sys.argv[1:]
    if len(a) == 3 and a[0] == 'make':
        make(a[1], a[2])
    elif len(a) == 5 and a[0] == 'run':
        run(a[1], a[2], a[3], a[4])
    elif len(a) == 4 and a[0] == 'score':
        score(a[1], a[2], a[3])
    else:
        sys.exit(__doc__)
