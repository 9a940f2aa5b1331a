# Blender's own BVH importer, run over many files in one Blender session, writing the world-space
# head position of every bone for the first, middle and last frame of each file. These are the
# reference positions that `tests/blender_fk.rs` compares anymo's forward kinematics with.
#
# Usage: blender -b --factory-startup --python-exit-code 1 --python tools/blender_fk_batch.py -- DATA_DIR LIST.txt OUT_DIR [ROTATE_MODE]
# ROTATE_MODE is the importer's rotate_mode: QUATERNION (default) keeps Blender's poses exact; NATIVE stores
# Euler curves in the file's order, which loses up to ~0.2 degrees in f32 near gimbal lock (middle angle near 90).
# LIST.txt holds one path per line (.bvh or .bvh.gz) relative to DATA_DIR; each result
# is written to OUT_DIR/<path with / replaced by +>.json with 0-based frame numbers as keys.
import bpy, sys, json, gzip, os, tempfile, builtins

_open = builtins.open
builtins.open = lambda f, mode='r', *a, **k: _open(f, mode.replace('U', ''), *a, **k)  # Blender 3.4 opens with 'rU'

argv = sys.argv[sys.argv.index('--') + 1:]
base, listing, out_dir = argv[0], argv[1], argv[2]
rotate_mode = argv[3] if len(argv) > 3 else 'QUATERNION'
os.makedirs(out_dir, exist_ok=True)
paths = [l.strip() for l in _open(listing) if l.strip()]
failed = 0
for rel in paths:
    src = os.path.join(base, rel)
    tmp = None
    text = (gzip.open(src) if src.endswith('.gz') else _open(src, 'rb')).read()
    # The clip's own frame count: Blender's scene range may be longer (it defaults to 250).
    count = int(text.split(b'Frames:', 1)[1].split()[0])
    if src.endswith('.gz'):
        tmp = tempfile.NamedTemporaryFile(suffix='.bvh', delete=False)
        tmp.write(text)
        tmp.close()
        src = tmp.name
    try:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.import_anim.bvh(filepath=src, global_scale=1.0, rotate_mode=rotate_mode, axis_forward='Y', axis_up='Z',
                                use_fps_scale=False, update_scene_fps=False, update_scene_duration=True)
        scene = bpy.context.scene
        arm = [o for o in scene.objects if o.type == 'ARMATURE'][0]
        frames = sorted({0, count // 2, count - 1})
        res = {'bones': [b.name for b in arm.pose.bones], 'frames': {}}
        for f in frames:
            scene.frame_set(scene.frame_start + f)
            res['frames'][f] = [[round(c, 5) for c in arm.matrix_world @ b.head] for b in arm.pose.bones]
        with _open(os.path.join(out_dir, rel.replace('/', '+') + '.json'), 'w') as fh:
            json.dump(res, fh, separators=(',', ':'))
    except Exception as e:  # report and go on: one bad file must not hide the others
        failed += 1
        print('FAILED', rel, e)
    finally:
        if tmp is not None:
            os.unlink(tmp.name)
print('OK', len(paths) - failed, 'of', len(paths), 'files')
