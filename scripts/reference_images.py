"""The images the reference scripts score, and their output: FCA's .npz photos by name, a video's
frames (every n-th with VIDEO:n) labelled VIDEO#frame; one TSV row per image with the best car
score and its box in image pixels."""
import cv2
import numpy as np


def images(args):
    """(label, BGR image) for each argument, in order."""
    for arg in args:
        if arg.endswith(".npz"):
            yield arg.rsplit("/", 1)[-1], np.load(arg)["img"]
            continue
        path, every = (arg.split(":") + ["1"])[:2]
        cap, k = cv2.VideoCapture(path), 0
        while True:
            ok, img = cap.read()
            if not ok:
                break
            if k % int(every) == 0:
                yield f"{path.rsplit('/', 1)[-1]}#{k}", img
            k += 1


def print_best(args, best_car):
    """The TSV of `best_car(image) -> (score, [x1, y1, x2, y2])` over the images of `args`."""
    print("image\tcar_score\tx1\ty1\tx2\ty2")
    for label, img in images(args):
        score, box = best_car(img)
        print(f"{label}\t{score:.5f}\t" + "\t".join(f"{v:.2f}" for v in box))
