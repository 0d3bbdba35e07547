"""Files in and out: case files, tooth meshes and scans, and scene export.

`case` (case files, read and validated whole), `casefields` (the reader each field goes through),
`ligamentfields` (the `[ligament]` and `[[anchorage]]` tables),
`target` (a set-up's `[start]` and `[target]`: movements in the tooth's own terms, target meshes
registered to the start), `meshload` (STL/OBJ/PLY teeth into tooth models), `meshfolder` (a folder
of tooth meshes), `openfulljaw`, `scanfolders` and `scanframe` (the Open-Full-Jaw layout and a
scan's frame), `labelledscan` (Teeth3DS-style labelled intraoral scans), `scene_export` (posed teeth
as GLB or PLY), `shippedcases` (the case files orthosim ships), `shareddata` (where the shared real
data lives).
"""
