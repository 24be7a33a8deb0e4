// Prints OpenEXR's own ImfEnvmap results, the oracle for lumitrace.cubemap's tests.
//
// Reads whitespace-separated commands from stdin, one result line per command:
//   F sof x y z        CubeMap::faceAndPixelPosition of direction (x, y, z) for a
//                      sof x 6*sof cube map, then CubeMap::pixelPosition of the result:
//                      prints "face pif.x pif.y pos.x pos.y"
//   D sof face px py   CubeMap::direction and CubeMap::pixelPosition of position in face
//                      (px, py): prints "dir.x dir.y dir.z pos.x pos.y"
//   L w h x y          LatLongMap::direction of pixel (x, y) of a w x h lat-long map:
//                      prints "dir.x dir.y dir.z"
// Build: g++ -O1 imf_envmap_probe.cpp $(pkg-config --cflags --libs OpenEXR)
#include <ImfEnvmap.h>
#include <ImathBox.h>
#include <ImathVec.h>

#include <cstdio>
#include <iostream>
#include <string>

using IMATH_NAMESPACE::Box2i;
using IMATH_NAMESPACE::V2f;
using IMATH_NAMESPACE::V2i;
using IMATH_NAMESPACE::V3f;

static Box2i
cubeWindow (int sof)
{
    return Box2i (V2i (0, 0), V2i (sof - 1, 6 * sof - 1));
}

int
main ()
{
    std::string cmd;
    while (std::cin >> cmd)
    {
        if (cmd == "F")
        {
            int   sof;
            float x, y, z;
            std::cin >> sof >> x >> y >> z;
            Box2i                dw = cubeWindow (sof);
            Imf::CubeMapFace     face;
            V2f                  pif;
            Imf::CubeMap::faceAndPixelPosition (V3f (x, y, z), dw, face, pif);
            V2f pos = Imf::CubeMap::pixelPosition (face, dw, pif);
            std::printf (
                "%d %.9g %.9g %.9g %.9g\n", int (face), pif.x, pif.y, pos.x, pos.y);
        }
        else if (cmd == "D")
        {
            int   sof, face;
            float px, py;
            std::cin >> sof >> face >> px >> py;
            Box2i dw  = cubeWindow (sof);
            V2f   pif (px, py);
            V3f   dir = Imf::CubeMap::direction (Imf::CubeMapFace (face), dw, pif);
            V2f   pos = Imf::CubeMap::pixelPosition (Imf::CubeMapFace (face), dw, pif);
            std::printf (
                "%.9g %.9g %.9g %.9g %.9g\n", dir.x, dir.y, dir.z, pos.x, pos.y);
        }
        else if (cmd == "L")
        {
            int   w, h;
            float x, y;
            std::cin >> w >> h >> x >> y;
            Box2i dw (V2i (0, 0), V2i (w - 1, h - 1));
            V3f   dir = Imf::LatLongMap::direction (dw, V2f (x, y));
            std::printf ("%.9g %.9g %.9g\n", dir.x, dir.y, dir.z);
        }
        else
        {
            std::fprintf (stderr, "unknown command %s\n", cmd.c_str ());
            return 2;
        }
    }
    return 0;
}
