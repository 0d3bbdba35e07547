"""Files in and out: case files, tooth meshes and scans, and scene export.

`case` (case files, read and validated whole), `meshload` (STL/OBJ/PLY teeth into tooth models),
`openfulljaw`, `scanfolders` and `scanframe` (the Open-Full-Jaw layout and a scan's frame),
`scene_export` (posed teeth as GLB or PLY), `shareddata` (where the shared real data lives).
"""
