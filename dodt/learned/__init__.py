"""The optional learned person detector (the paper's YOLO-MAD): a small FastestDet-style network
trained on our own renders, run through onnxruntime, its 2D boxes lifted to 3D by the median
absolute deviation of the depth inside them and fused with the ensemble's boxes."""
