# Blender's own glTF importer as the reference for anymo's: imports each GLB listed, plays every
# animation at 30 fps, and writes the world-space head position of every bone (converted back to
# glTF's Y-up axes) for the first, middle and last frame of each animation.
#
# Usage: blender -b --factory-startup --python-exit-code 1 --python tools/blender_gltf_fk.py -- DATA_DIR LIST.txt OUT_DIR
# LIST.txt holds one .glb path per line relative to DATA_DIR; results go to
# OUT_DIR/<path with / replaced by +>.json as {"animations": {name: {"bones": [...], "frames": {frame: [[x, y, z], ...]}}}}.
import bpy, sys, json, os
import numpy

numpy.bool = bool  # Blender 3.4's glTF importer uses the alias that NumPy 1.24 removed (Debian's python3-numpy)

argv = sys.argv[sys.argv.index('--') + 1:]
base, listing, out_dir = argv[0], argv[1], argv[2]
os.makedirs(out_dir, exist_ok=True)
FPS = 30
failed = 0
paths = [l.strip() for l in open(listing) if l.strip()]
for rel in paths:
    try:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.fps = FPS
        scene.render.fps_base = 1.0
        bpy.ops.import_scene.gltf(filepath=os.path.join(base, rel))
        arm = max((o for o in scene.objects if o.type == 'ARMATURE'), key=lambda o: len(o.pose.bones))
        if arm.animation_data is None:
            arm.animation_data_create()
        result = {}
        for action in bpy.data.actions:
            # Channels an animation does not key hold the rest pose in glTF; Blender would keep
            # whatever the previous action left there, so reset the pose first.
            arm.animation_data.action = None
            for b in arm.pose.bones:
                b.location = (0, 0, 0)
                b.rotation_quaternion = (1, 0, 0, 0)
                b.rotation_euler = (0, 0, 0)
                b.scale = (1, 1, 1)
            arm.animation_data.action = action
            start, end = action.frame_range
            count = int(round(end - start)) + 1
            frames = sorted({0, count // 2, count - 1})
            entry = {'bones': [b.name for b in arm.pose.bones], 'start': start, 'frames': {}}
            for f in frames:
                scene.frame_set(int(round(start)) + f)
                heads = [arm.matrix_world @ b.head for b in arm.pose.bones]
                entry['frames'][f] = [[round(h.x, 5), round(h.z, 5), round(-h.y, 5)] for h in heads]
            result[action.name] = entry
        with open(os.path.join(out_dir, rel.replace('/', '+') + '.json'), 'w') as fh:
            json.dump({'animations': result}, fh, separators=(',', ':'))
    except Exception as e:  # report and go on
        failed += 1
        print('FAILED', rel, e)
print('OK', len(paths) - failed, 'of', len(paths), 'files')
